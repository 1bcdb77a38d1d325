"""Placing a candidate pool on the 7x7 difficulty x complexity grid."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from glocal_ros.tasks import COMPLEXITY_LEVELS, DIFFICULTY_LEVELS

BINNING_METHOD = (
    "digit: complexity septile over all valid candidates (edges at the 1/7..6/7 "
    "quantiles); letter: within each digit's candidates sorted by difficulty, the "
    "7 evenly spaced order statistics (easiest = A, hardest = G). Complexity and "
    "difficulty are correlated, so global difficulty bins would leave the "
    "simple-hard and complex-easy corners empty; ranking within a column fills "
    "every cell while keeping both orders."
)


#: What a measured grid's letters can follow: the measure's name and when a candidate counts as usable.
LETTER_MEASURES: dict[str, tuple[str, str]] = {
    "perturbed grasp": ("perturbed-grasp success", "the scripted grasp lifts reliably"),
    "lifting poses": ("share of top-down poses that lift it", "the best of those poses lifts reliably"),
}


def measured_binning_method(letter_by: str = "perturbed grasp") -> str:
    """How ``assign_measured_grid`` places candidates, when its letters follow ``letter_by``."""
    measure, usable = LETTER_MEASURES[letter_by]
    return (
        "digit: complexity septile over all valid candidates, as for the geometric grid; "
        "letter: within each digit, a shortlist of candidates evenly spaced in geometric "
        f"difficulty is built and measured in the simulator; among those {usable}, row r "
        f"takes the candidate whose {measure} is nearest to the r-th of 7 values evenly spaced "
        "from the column's highest (A) to its lowest (G). Evenly spaced values rather than "
        "order statistics: a column whose shortlist crowds at one end still gets its easiest "
        "and its hardest object."
    )


class GridAssignmentError(ValueError):
    """Too few candidates to fill every cell."""


@dataclass(frozen=True)
class GridAssignment:
    """``cells[task]`` is the index into the candidate sequence for that task."""

    cells: dict[str, int]
    complexity_edges: list[float]


def assign_grid(complexity: Sequence[float], difficulty: Sequence[float]) -> GridAssignment:
    """Choose one candidate per task from parallel metric sequences (see ``BINNING_METHOD``)."""
    columns, edges = shortlist(complexity, difficulty, len(DIFFICULTY_LEVELS))
    cells = {letter + digit: members[row]
             for digit, members in columns.items() for row, letter in enumerate(DIFFICULTY_LEVELS)}
    return GridAssignment(cells=cells, complexity_edges=edges)


def shortlist(complexity: Sequence[float], difficulty: Sequence[float],
              per_column: int) -> tuple[dict[str, list[int]], list[float]]:
    """Per complexity digit, ``per_column`` candidate indices evenly spaced in ``difficulty`` (easiest
    first; all of the column's if it has fewer), and the complexity septile edges.

    Raises ``GridAssignmentError`` if a column has fewer than 7 candidates.
    """
    c = np.asarray(complexity, dtype=float)
    d = np.asarray(difficulty, dtype=float)
    n_cols, n_rows = len(COMPLEXITY_LEVELS), len(DIFFICULTY_LEVELS)
    if len(c) < n_cols * n_rows:
        raise GridAssignmentError(f"need at least {n_cols * n_rows} candidates, got {len(c)}")
    edges = np.quantile(c, np.arange(1, n_cols) / n_cols)
    column = np.searchsorted(edges, c, side="right")
    columns: dict[str, list[int]] = {}
    for col, digit in enumerate(COMPLEXITY_LEVELS):
        members = np.flatnonzero(column == col)
        if len(members) < n_rows:
            raise GridAssignmentError(f"complexity column {digit} has only {len(members)} candidates")
        # Stable sort on (difficulty, index) keeps ties deterministic.
        ranked = members[np.lexsort((members, d[members]))]
        picks = np.round(np.linspace(0, len(ranked) - 1, min(per_column, len(ranked)))).astype(int)
        columns[digit] = [int(ranked[pick]) for pick in picks]
    return columns, [float(e) for e in edges]


def assign_measured_grid(columns: Mapping[str, Sequence[int]], success: Mapping[int, float],
                         complexity_edges: Sequence[float]) -> GridAssignment:
    """Letters from success measured in the simulator (see ``measured_binning_method``).

    ``columns``: each digit's measured candidates; ``success``: each usable candidate's perturbed-grasp
    success (candidates missing from it are left out). Raises ``GridAssignmentError`` if a column has
    fewer than 7 usable candidates.
    """
    cells: dict[str, int] = {}
    for digit, members in columns.items():
        usable = sorted((m for m in members if m in success), key=lambda m: (-success[m], m))
        if len(usable) < len(DIFFICULTY_LEVELS):
            raise GridAssignmentError(f"complexity column {digit} has only {len(usable)} usable measured "
                                      "candidates")
        targets = np.linspace(success[usable[0]], success[usable[-1]], len(DIFFICULTY_LEVELS))
        for row, (letter, target) in enumerate(zip(DIFFICULTY_LEVELS, targets)):
            # Nearest to the target among those that leave enough candidates for the rows below, so the
            # column stays ordered: row r picks from usable[r .. len - 7 + r], after the previous pick.
            low = usable.index(cells[DIFFICULTY_LEVELS[row - 1] + digit]) + 1 if row else 0
            high = len(usable) - len(DIFFICULTY_LEVELS) + row
            window = usable[low:high + 1]
            cells[letter + digit] = min(window, key=lambda m: (abs(success[m] - target), m))
    return GridAssignment(cells=cells, complexity_edges=list(complexity_edges))
