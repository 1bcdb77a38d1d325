"""The paper's task set: one object per task on the 7x7 EGAD evaluation grid.

Task names are ``<letter><digit>``: the letter is grasp difficulty (``A``
easiest .. ``G`` hardest), the digit shape complexity (``0`` simplest ..
``6``). ``A0`` is the task the prior policy is trained on.

A novel object, outside the set, is the task ``<name>@<proxy>`` (``novel_task``):
the object of the directory ``<name>`` (letters, digits, ``_`` and ``-``, a
letter first, not a grid name in any case), served under the one-hot bit of the
grid task ``<proxy>``. The observation has one bit per grid task and the stored
policies' input layers are that wide, so a 50th object cannot have a bit of its
own without every policy losing its meaning; it borrows one. Which one is the
user's choice: ``glocal-ros adapt`` presents the object to each policy under
the bit of the task that policy last trained on (a global policy's global task,
the prior's A0), so that to the policy it looks like the task it knows and only
the shape is new. Both learner profiles treat the bit the same way: it is an
input like any other, and a goal whose task's bit the policy trained on edits
no input weights (``learner_node.fine_tuning``). The sim, the learner and the
recorder serve novel tasks (``check_task``); a curriculum's task set is the grid
(``validate_tasks``).
"""

from __future__ import annotations

import re
from typing import Iterable, Sequence

DIFFICULTY_LEVELS = "ABCDEFG"
COMPLEXITY_LEVELS = "0123456"

ALL_TASKS: tuple[str, ...] = tuple(d + c for d in DIFFICULTY_LEVELS for c in COMPLEXITY_LEVELS)
NUM_TASKS = len(ALL_TASKS)
PRIOR_TASK = "A0"

_INDEX = {task: i for i, task in enumerate(ALL_TASKS)}


NOVEL_SEPARATOR = "@"
_NOVEL_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")


class UnknownTaskError(ValueError):
    """A task name that is not on the A0..G6 grid (or, where novel tasks are served, not a novel task)."""


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


def check_novel_name(name: str) -> str:
    """``name`` if it can name a novel object: ``UnknownTaskError`` if it is malformed or a grid task's name."""
    if not _NOVEL_NAME.fullmatch(name):
        raise UnknownTaskError(f"invalid object name {name!r}: a letter, then letters, digits, '_' or '-', "
                               f"at most 64")
    if name.upper() in _INDEX:
        raise UnknownTaskError(f"object name {name!r} collides with grid task {name.upper()}: the set's objects "
                               f"are A0..G6; choose another name")
    return name


def novel_task(name: str, proxy: str) -> str:
    """The task of the novel object ``name`` served under ``proxy``'s one-hot bit: ``name@proxy``."""
    task_index(proxy)
    return f"{check_novel_name(name)}{NOVEL_SEPARATOR}{proxy}"


def split_novel_task(task: str) -> tuple[str, str] | None:
    """``(name, proxy)`` of a well-formed novel task, None for any other string."""
    name, separator, proxy = task.partition(NOVEL_SEPARATOR)
    if not separator or proxy not in _INDEX or not _NOVEL_NAME.fullmatch(name) or name.upper() in _INDEX:
        return None
    return name, proxy


def check_task(task: str) -> str:
    """``task`` if the sim and the learner can serve it: a grid task or a novel one, else ``UnknownTaskError``."""
    if task in _INDEX or split_novel_task(task) is not None:
        return task
    if NOVEL_SEPARATOR in task:
        name, _, proxy = task.partition(NOVEL_SEPARATOR)
        check_novel_name(name)
        task_index(proxy)
    raise UnknownTaskError(f"unknown task {task!r}: expected A0..G6, or NAME@A0..G6 for a novel object")


def check_tasks(tasks: Iterable[str]) -> list[str]:
    """``tasks`` as a list, each checked by ``check_task``."""
    return [check_task(task) for task in tasks]


def grid_task(task: str) -> str:
    """The grid task whose one-hot bit ``task`` has: itself, or a novel task's proxy."""
    novel = split_novel_task(task)
    return novel[1] if novel else task


def one_hot_bit(task: str) -> int:
    """The observation's one-hot bit of ``task``: its grid index, or a novel task's proxy's."""
    return task_index(grid_task(task))


def object_name(task: str) -> str:
    """The directory of ``task``'s object in an objects folder: the grid task itself, or the novel name."""
    novel = split_novel_task(check_task(task))
    return novel[0] if novel else task


def validate_tasks(tasks: Iterable[str]) -> list[str]:
    """Return ``tasks`` as a list, raising ``UnknownTaskError`` on the first unknown name."""
    checked = list(tasks)
    for task in checked:
        task_index(task)
    return checked


def parse_task_list(text: str, novel: bool = False) -> list[str]:
    """Parse ``"A0,B3"`` or ``"all"`` into task names; with ``novel``, ``NAME@PROXY`` too (``check_task``).

    Grid names and proxies are upper-cased; a novel object's name is kept as given (it names a directory).
    """
    text = text.strip()
    if text.lower() == "all":
        return list(ALL_TASKS)
    parts = [part.strip() for part in text.split(",") if part.strip()]
    if not parts:
        raise UnknownTaskError("no task given")
    if not novel:
        return validate_tasks(part.upper() for part in parts)
    tasks = []
    for part in parts:
        name, separator, proxy = part.partition(NOVEL_SEPARATOR)
        tasks.append(check_task(f"{name}{separator}{proxy.upper()}" if separator else part.upper()))
    return tasks


def sorted_tasks(tasks: Sequence[str]) -> list[str]:
    """``tasks`` in grid order (A0, A1, .., G6)."""
    return sorted(tasks, key=task_index)
