"""SAC settings of the project, chosen for wall-clock on a 2-core CPU.

One torch thread was fastest on 2 cores (the other core steps physics);
[256, 256] networks, batch 256 and one gradient step per env step (UTD 1)
are what the grasp probe of ENVIRONMENT.md learned with; gamma 0.95 suits
T = 50 step episodes with a -1 per step reward. ``gradient_steps=-1`` is
SB3's "as many as env steps collected": one per env step whatever the
number of envs N, so N changes wall-clock, not sample efficiency.
"""

from __future__ import annotations

from typing import Any

TORCH_THREADS = 1

SAC_KWARGS: dict[str, Any] = dict(
    learning_rate=3e-4,
    buffer_size=200_000,
    batch_size=256,
    gamma=0.95,
    tau=0.005,
    train_freq=1,
    gradient_steps=-1,
    ent_coef="auto",
    policy_kwargs=dict(net_arch=[256, 256]),
)

#: Settings a Train goal applies to a loaded model too (stored models keep those they were saved with).
SCHEDULE_KEYS = ("batch_size", "gradient_steps")
