"""GloCAL (Algorithm 1 of the paper) and its two ablations.

Per iteration m: evaluate pi_curr on the remaining tasks; cluster them by
score (``glocal_ros.clustering``); take C_1, the best cluster; train pi_curr
on its global task (the ceil-median) into pi_G,m; train the local tasks as a
chain from pi_G,m (pi_L,m,i from pi_L,m,i-1); pi_curr = pi_G,m. A task is
learned when its score passes B within its training budget; otherwise it
returns to the pool for the next iteration.

Ablations: ``glocal_random_cluster`` picks a cluster uniformly instead of
C_1. ``glocal_no_global`` has no global task: "a policy trained over all
tasks within the cluster", one that "arbitrarily sweeps through all tasks
within the cluster", is the prior for the next iteration. It is one policy
trained from pi_curr on each task of C_1 in turn, in an order drawn at
random, with the per-task rule of Algorithm 1 (each task until its score
passes B or its budget is spent); a task is learned by the policy as it
was when it passed, and the policy at the end of the sweep is pi_curr.

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
- The sweep of ``glocal_no_global`` goes on from each task's policy whether
  the task was learned or not (it is one policy through the whole cluster,
  unlike the local chain), and a task it did not learn returns to the pool.
- An iteration whose clustering leaves no task it could train (all budget
  spent) ends the run; so do an empty pool and ``max_iter``.

Parallel locals (``parallel_locals: true``, GloCAL and
``glocal_random_cluster``; ``glocal_no_global``'s sweep is one policy
through the cluster, so each of its tasks waits for the one before, as do
the baselines). The local tasks of iteration m need only pi_G,m, so they go
out as soon as it exists, each to the next free learner, while the run goes
on to iteration m+1. One loop runs both: without ``parallel_locals`` every
call is waited for before the next is asked (the K = 1 case of the run's
scheduler, ``glocal_ros.curriculum.run``). The orderings that change, against
the sequential run:
- Every local task of iteration m starts from pi_G,m: there is no chain
  (pi_L,m,i does not start from pi_L,m,i-1).
- Iteration m+1 starts while locals of m are in flight: it evaluates
  pi_curr = pi_G,m on the remaining tasks that are not in flight (a task
  in flight is neither clustered nor trained twice at once), clusters them
  and trains its global task. A local that ends unlearned returns to the
  pool and is scored by the first evaluation after it ends.
- A task counts as learned, and its step as the run's total, when its goal's
  answer comes, in the order answers come (so learned_at_steps is a function
  of the completion order, which the journal keeps).
- The budget counts the steps reserved by goals in flight: a goal is clipped
  to what is left after them. When none is left, the run waits for a goal to
  end (and hand back what it did not use) before it starts an iteration, and
  one that finds no steps left after its evaluation trains nothing and goes on.
- When every remaining task is in flight, the run waits for an answer.
- Seeds come from the run seed and the call's key (``m3/local/B1``), not the
  call's place.
With one learner, the calls are queued first in, first out: the locals of m
then run before the evaluation of m+1, whose pool still leaves them out.
"""

from __future__ import annotations

import numpy as np

from glocal_ros.clustering import cluster_tasks, split_global_local
from glocal_ros.curriculum.learner import TrainGoal, TrainResult
from glocal_ros.curriculum.codes import ROLE_CLUSTER, ROLE_GLOBAL, ROLE_LOCAL
from glocal_ros.curriculum.run import Run


def run_glocal(run: Run, ablation: str = "") -> None:
    """GloCAL; ``ablation`` is "", "no_global" or "random_cluster"."""
    if ablation not in ("", "no_global", "random_cluster"):
        raise ValueError(f"unknown GloCAL ablation {ablation!r}")
    config = run.config
    rng = np.random.default_rng(config.seed)
    current = config.initial_policy
    iteration = 0
    while iteration < config.max_iter and not run.over:
        idle = [task for task in run.state.remaining_tasks if task not in run.tasks_in_flight]
        if not idle or run.steps_left == 0:
            run.wait_any()  # something is in flight, or the run would be over
            continue
        iteration += 1
        run.begin_iteration(iteration)
        key = f"m{iteration}"
        scores = run.evaluate(current, idle, f"{key}/evaluate")
        clustering = cluster_tasks(scores, config.k_min, config.k_max, seed=config.seed + iteration)
        chosen = int(rng.integers(len(clustering.clusters))) if ablation == "random_cluster" else 0
        cluster = clustering.clusters[chosen]

        if ablation == "no_global":
            sweep = [cluster.tasks[i] for i in rng.permutation(len(cluster.tasks))]
            run.show_clustering(clustering, chosen, "", sweep)
            current = _train_tasks(run, ROLE_CLUSTER, current, sweep, f"C{iteration}", f"{key}/cluster",
                                   hand_on="every")
        else:
            global_task, local_tasks = split_global_local(cluster)
            run.show_clustering(clustering, chosen, global_task, local_tasks)
            if run.steps_left == 0:
                continue
            global_policy = config.policy_name(f"G{iteration}")
            run.wait_for(_start_task(run, ROLE_GLOBAL, global_task, current, global_policy,
                                     f"{key}/global/{global_task}"))
            _train_tasks(run, ROLE_LOCAL, global_policy, local_tasks, f"L{iteration}", f"{key}/local",
                         hand_on="none" if config.parallel_locals else "learned")
            current = global_policy
        run.set_current_policy(current)
    run.wait_all()
    run.finish()


def _train_tasks(run: Run, role: int, first: str, tasks: list[str], names: str, key: str, hand_on: str) -> str:
    """Train ``tasks`` in turn, the first from policy ``first``; their outputs are ``names``_0, _1, ...
    and their calls ``key``/<task>. Each next task starts from the policy handed on: every task's output
    (``hand_on="every"``: the sweep of one policy), the output of the last task learned (``"learned"``:
    the local chain), or none (``"none"``: every task from ``first``, all queued at once for the free
    learners, not waited for). Returns the last policy handed on."""
    policy = first
    for index, task in enumerate(tasks):
        if run.steps_left == 0:
            break
        output = run.config.policy_name(f"{names}_{index}")
        call = _start_task(run, role, task, policy, output, f"{key}/{task}")
        if hand_on == "none":
            continue
        run.wait_for(call)
        if hand_on == "every" or run.is_learned(task):
            policy = output
    return policy


def _start_task(run: Run, role: int, task: str, initial: str, output: str, key: str) -> str:
    """Queue ``task`` until learned or out of its budget; marked learned when its answer says so."""
    def done(result: TrainResult) -> None:
        if result.learned:
            run.mark_learned(task, output)

    config = run.config
    return run.start_train(role, TrainGoal(
        task=task, initial_policy=initial, output_policy=output, step_budget=config.task_step_budget,
        eval_interval=config.eval_interval, stop_when_learned=True,
    ), key, done)
