import pytest

from glocal_ros.tasks import (
    ALL_TASKS, NUM_TASKS, UnknownTaskError, check_novel_name, check_task, grid_coordinates, grid_task,
    novel_task, object_name, one_hot_bit, parse_task_list, sorted_tasks, split_novel_task, task_index,
    validate_tasks,
)


def test_grid_is_7x7_in_row_major_order():
    assert NUM_TASKS == 49
    assert ALL_TASKS[0] == "A0" and ALL_TASKS[6] == "A6" and ALL_TASKS[7] == "B0" and ALL_TASKS[-1] == "G6"
    assert [task_index(t) for t in ALL_TASKS] == list(range(49))
    assert grid_coordinates("C4") == (2, 4)


def test_parse_task_list():
    assert parse_task_list("a0, B3") == ["A0", "B3"]
    assert parse_task_list("all") == list(ALL_TASKS)
    with pytest.raises(UnknownTaskError, match="H1"):
        parse_task_list("A0,H1")
    with pytest.raises(UnknownTaskError):
        parse_task_list(" , ")
    with pytest.raises(UnknownTaskError, match="MUG@C4"):
        parse_task_list("a0,mug@c4")  # a curriculum's tasks are the grid
    assert parse_task_list("a0, Mug@c4", novel=True) == ["A0", "Mug@C4"]  # the name is a directory's: as given
    with pytest.raises(UnknownTaskError, match="collides with grid task B3"):
        parse_task_list("b3@A0", novel=True)


def test_sorted_tasks_uses_grid_order():
    assert sorted_tasks(["B0", "A6", "A1"]) == ["A1", "A6", "B0"]


def test_a_novel_object_is_served_under_its_proxys_bit_and_never_in_a_curriculums_set():
    task = novel_task("mug_2", "C4")
    assert task == "mug_2@C4" and split_novel_task(task) == ("mug_2", "C4")
    assert check_task(task) == task and check_task("B3") == "B3"
    assert one_hot_bit(task) == task_index("C4") and grid_task(task) == "C4" and grid_task("B3") == "B3"
    assert object_name(task) == "mug_2" and object_name("B3") == "B3"
    assert split_novel_task("B3") is None and split_novel_task("mug@H9") is None
    with pytest.raises(UnknownTaskError, match="NAME@A0..G6"):
        check_task("mug")
    for refused, message in (("b3@A0", "collides with grid task B3"), ("2mug@A0", "invalid object name"),
                             ("mug@H9", "unknown task 'H9'"), ("mug@", "unknown task ''")):
        with pytest.raises(UnknownTaskError, match=message):
            check_task(refused)
    with pytest.raises(UnknownTaskError, match="collides with grid task G6"):
        check_novel_name("g6")
    with pytest.raises(UnknownTaskError, match="invalid object name"):
        check_novel_name("mug\n")  # a name is a directory's: the whole of it is checked
    assert split_novel_task("mug\n@C4") is None
    with pytest.raises(UnknownTaskError):
        validate_tasks([task])  # a run's task set is the grid
