"""GloCAL (Algorithm 1 of the paper) and its two ablations.

Per iteration m: evaluate pi_curr on the remaining tasks; cluster them by
score (``glocal_ros.clustering``); take C_1, the best cluster; train pi_curr
on its global task (the ceil-median) into pi_G,m; train the local tasks as a
chain from pi_G,m (pi_L,m,i from pi_L,m,i-1); pi_curr = pi_G,m. A task is
learned when its score passes B within its training budget; otherwise it
returns to the pool for the next iteration.

Ablations: ``glocal_random_cluster`` picks a cluster uniformly instead of
C_1; ``glocal_no_global`` trains pi_curr on all tasks of C_1 at once (each
episode's task in turn) and that cluster policy, not a global task's, is
the prior for the local tasks and for the next iteration.

Choices the paper leaves open, made here:
- "Train until S > B" checks the score before training, then every
  ``eval_interval`` training steps and at the end of the task's budget; the
  goal stops at the first check that passes (a task its starting policy
  already grasps costs one evaluation and no training).
- pi_G,m is the policy trained on the global task even when the task was not
  learned within its budget: the paper's pi_G,m is "pi_curr after that
  training session".
- The local chain continues from the last policy that learned its task: a
  local task that failed does not hand its policy on.
- The cluster policy of ``glocal_no_global`` trains for the per-task budget
  times the cluster's size (what GloCAL could spend on the cluster), and is
  then evaluated on each cluster task; those above B are learned by it, the
  others are trained as local tasks from it.
- An iteration whose clustering leaves no task it could train (all budget
  spent) ends the run; so do an empty pool and ``max_iter``.
"""

from __future__ import annotations

import numpy as np

from glocal_ros.clustering import cluster_tasks, split_global_local
from glocal_ros.curriculum.learner import TrainRequest, passes_threshold
from glocal_ros.curriculum.codes import ROLE_CLUSTER, ROLE_GLOBAL, ROLE_LOCAL
from glocal_ros.curriculum.run import Run


def run_glocal(run: Run, ablation: str = "") -> None:
    """GloCAL; ``ablation`` is "", "no_global" or "random_cluster"."""
    if ablation not in ("", "no_global", "random_cluster"):
        raise ValueError(f"unknown GloCAL ablation {ablation!r}")
    config = run.config
    rng = np.random.default_rng(config.seed)
    current = config.initial_policy
    for iteration in range(1, config.max_iter + 1):
        if run.over:
            break
        run.begin_iteration(iteration)
        remaining = list(run.state.remaining_tasks)
        scores = run.evaluate(current, remaining)
        clustering = cluster_tasks(scores, config.k_min, config.k_max, seed=config.seed + iteration)
        chosen = int(rng.integers(len(clustering.clusters))) if ablation == "random_cluster" else 0
        cluster = clustering.clusters[chosen]

        if ablation == "no_global":
            run.show_clustering(clustering, chosen, "", list(cluster.tasks))
            prior = _train_cluster(run, current, list(cluster.tasks), iteration)
            local_tasks = [task for task in cluster.tasks if not run.is_learned(task)]
        else:
            global_task, local_tasks = split_global_local(cluster)
            run.show_clustering(clustering, chosen, global_task, local_tasks)
            prior = config.policy_name(f"G{iteration}")
            _train_task(run, ROLE_GLOBAL, global_task, current, prior)

        policy = prior
        for index, task in enumerate(local_tasks):
            if run.over:
                break
            output = config.policy_name(f"L{iteration}_{index}")
            if _train_task(run, ROLE_LOCAL, task, policy, output):
                policy = output
        current = prior
        run.set_current_policy(current)
    run.finish()


def _train_task(run: Run, role: int, task: str, initial: str, output: str) -> bool:
    """Train ``task`` until learned or out of its budget; True when learned."""
    if run.over:
        return False
    config = run.config
    result = run.train(role, TrainRequest(
        task=task, initial_policy=initial, output_policy=output, step_budget=config.task_step_budget,
        eval_interval=config.eval_interval, stop_when_learned=True,
    ))
    if result.learned:
        run.mark_learned(task, output)
    return result.learned


def _train_cluster(run: Run, initial: str, tasks: list[str], iteration: int) -> str:
    """``glocal_no_global``: one policy over all tasks of the cluster; marks those it learned."""
    config = run.config
    output = config.policy_name(f"C{iteration}")
    run.train(ROLE_CLUSTER, TrainRequest(
        task="", episode_tasks=tuple(tasks), initial_policy=initial, output_policy=output,
        step_budget=config.task_step_budget * len(tasks), stop_when_learned=False,
    ))
    for task, score in run.evaluate(output, tasks).items():
        if passes_threshold(score, config.threshold):
            run.mark_learned(task, output)
    return output
