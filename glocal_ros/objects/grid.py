"""Placing a candidate pool on the 7x7 difficulty x complexity grid."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

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


class GridAssignmentError(ValueError):
    """Too few candidates to fill every cell."""


@dataclass(frozen=True)
class GridAssignment:
    """``cells[task]`` is the index into the candidate sequence for that task."""

    cells: dict[str, int]
    complexity_edges: list[float]


def assign_grid(complexity: Sequence[float], difficulty: Sequence[float]) -> GridAssignment:
    """Choose one candidate per task from parallel metric sequences (see ``BINNING_METHOD``)."""
    c = np.asarray(complexity, dtype=float)
    d = np.asarray(difficulty, dtype=float)
    n_cols, n_rows = len(COMPLEXITY_LEVELS), len(DIFFICULTY_LEVELS)
    if len(c) < n_cols * n_rows:
        raise GridAssignmentError(f"need at least {n_cols * n_rows} candidates, got {len(c)}")
    edges = np.quantile(c, np.arange(1, n_cols) / n_cols)
    column = np.searchsorted(edges, c, side="right")
    cells: dict[str, int] = {}
    for col, digit in enumerate(COMPLEXITY_LEVELS):
        members = np.flatnonzero(column == col)
        if len(members) < n_rows:
            raise GridAssignmentError(f"complexity column {digit} has only {len(members)} candidates")
        # Stable sort on (difficulty, index) keeps ties deterministic.
        ranked = members[np.lexsort((members, d[members]))]
        picks = np.round(np.linspace(0, len(ranked) - 1, n_rows)).astype(int)
        for row, letter in enumerate(DIFFICULTY_LEVELS):
            cells[letter + digit] = int(ranked[picks[row]])
    return GridAssignment(cells=cells, complexity_edges=[float(e) for e in edges])
