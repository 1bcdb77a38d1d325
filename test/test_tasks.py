import pytest

from glocal_ros.tasks import (
    ALL_TASKS, NUM_TASKS, UnknownTaskError, grid_coordinates, parse_task_list, sorted_tasks, task_index,
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


def test_sorted_tasks_uses_grid_order():
    assert sorted_tasks(["B0", "A6", "A1"]) == ["A1", "A6", "B0"]
