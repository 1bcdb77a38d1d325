"""Seeds derived from a seed: independent, repeatable random streams for the parts of a run.

A run has one seed. Each call the curriculum makes of the learner, and each
stream inside a Train goal, takes a seed derived from it and from the call's
or stream's place (numpy's ``SeedSequence``, whose children are independent
streams), so that what a call does depends on the run seed and on where the
call stands in the run, never on what ran before it on the same processes.
"""

from __future__ import annotations

import numpy as np

#: Seeds go through ROS int64 fields, Gymnasium and torch: 0..2^31-1 fits them all.
MAX_SEED = 2**31 - 1


def derived_seed(seed: int, *keys: int) -> int:
    """The seed, in 0..MAX_SEED, of the stream that ``keys`` name under ``seed``."""
    return int(np.random.SeedSequence([seed, *keys]).generate_state(1)[0]) & MAX_SEED
