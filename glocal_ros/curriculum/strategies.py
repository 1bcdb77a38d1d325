"""The strategies by the names that parameters and the CLI use."""

from __future__ import annotations

from typing import Callable

from glocal_ros.curriculum.baselines import run_alp_gmm, run_random
from glocal_ros.curriculum.glocal import run_glocal
from glocal_ros.curriculum.run import Run
from glocal_ros.sim_contract import DEFAULT_EPISODE_STEPS

#: The ALP-GMM baselines by name: episodes between refits of the sampler (each goal is one such chunk).
ALP_GMM_FIT_RATES = {"alp_gmm_250": 250, "alp_gmm_10": 10}

#: name -> ``strategy(run, max_episode_steps)``.
STRATEGIES: dict[str, Callable[[Run, int], None]] = {
    "glocal": lambda run, max_episode_steps: run_glocal(run),
    "random": run_random,
    **{name: lambda run, max_episode_steps, rate=rate: run_alp_gmm(run, rate, max_episode_steps)
       for name, rate in ALP_GMM_FIT_RATES.items()},
    "glocal_no_global": lambda run, max_episode_steps: run_glocal(run, "no_global"),
    "glocal_random_cluster": lambda run, max_episode_steps: run_glocal(run, "random_cluster"),
}


def run_strategy(run: Run, max_episode_steps: int = DEFAULT_EPISODE_STEPS) -> None:
    """Run ``run.config.strategy`` to its end; ``max_episode_steps`` is the envs' T."""
    if run.config.strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {run.config.strategy!r}: expected one of {', '.join(STRATEGIES)}")
    STRATEGIES[run.config.strategy](run, max_episode_steps)
