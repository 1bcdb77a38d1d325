"""The paper's task set: one object per task on the 7x7 EGAD evaluation grid.

Task names are ``<letter><digit>``: the letter is grasp difficulty (``A``
easiest .. ``G`` hardest), the digit shape complexity (``0`` simplest ..
``6``). ``A0`` is the task the prior policy is trained on.
"""

from __future__ import annotations

from typing import Iterable, Sequence

DIFFICULTY_LEVELS = "ABCDEFG"
COMPLEXITY_LEVELS = "0123456"

ALL_TASKS: tuple[str, ...] = tuple(d + c for d in DIFFICULTY_LEVELS for c in COMPLEXITY_LEVELS)
NUM_TASKS = len(ALL_TASKS)
PRIOR_TASK = "A0"

_INDEX = {task: i for i, task in enumerate(ALL_TASKS)}


class UnknownTaskError(ValueError):
    """A task name that is not on the A0..G6 grid."""


def task_index(task: str) -> int:
    """Position of ``task`` in ``ALL_TASKS`` (the index of its one-hot bit)."""
    try:
        return _INDEX[task]
    except KeyError:
        raise UnknownTaskError(f"unknown task {task!r}: expected A0..G6") from None


def grid_coordinates(task: str) -> tuple[int, int]:
    """``(difficulty, complexity)``, each 0..6, of ``task``."""
    index = task_index(task)
    return divmod(index, len(COMPLEXITY_LEVELS))


def validate_tasks(tasks: Iterable[str]) -> list[str]:
    """Return ``tasks`` as a list, raising ``UnknownTaskError`` on the first unknown name."""
    checked = list(tasks)
    for task in checked:
        task_index(task)
    return checked


def parse_task_list(text: str) -> list[str]:
    """Parse ``"A0,B3"`` or ``"all"`` into task names."""
    text = text.strip()
    if text.lower() == "all":
        return list(ALL_TASKS)
    tasks = [part.strip().upper() for part in text.split(",") if part.strip()]
    if not tasks:
        raise UnknownTaskError("no task given")
    return validate_tasks(tasks)


def sorted_tasks(tasks: Sequence[str]) -> list[str]:
    """``tasks`` in grid order (A0, A1, .., G6)."""
    return sorted(tasks, key=task_index)
