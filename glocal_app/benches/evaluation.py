"""``glocal-ros bench eval``: evaluation through learner_node beside its floor, in the same rounds.

One sim_node with ``num_envs`` training envs and ``eval_envs`` evaluation
envs (both over its default workers) and one learner_node run as processes on
a ROS domain of their own. Per round, alternating:

- *floor*: ``eval_envs`` envs over the same number of worker processes, in
  this process, stepped with random actions (phase eval): the physics on
  every core the sim has, and nothing else; no evaluation can beat it;
- *via sim_node*: ``learner_node.evaluation.evaluate`` in this process on the
  sim_node's ``sim/step``, acting as learner_node would (the profile's
  ``evaluation_policy``), its env steps counted exactly;
- *learner_node*: the same request to ``learner/evaluate`` (policy, tasks,
  episodes and seed), timed from send to answer. A seeded evaluation is
  the same episodes whoever runs it, so its env steps are those counted via
  sim_node (the report lists both processes' scores: a difference says the
  two acted otherwise somewhere, and the env steps are then approximate);
- *on the training envs*: the same request to a second learner_node whose
  sim_node has ``eval_envs:=0``, so that its evaluations run on the
  ``num_envs`` training envs, as every evaluation did before evaluation had
  envs of its own.

Env steps include the uncounted episodes an env runs once the jobs ran
out (``evaluate``): physics the sim did. Episodes/s counts the evaluation's
own episodes, what a run's wall-clock feels.
"""

from __future__ import annotations

import os
import shutil
import statistics
import sys
import tempfile
import time
from contextlib import ExitStack, closing
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from glocal_app.processes import NodeProcess, isolated_environment, namespace_arguments
from glocal_ros.domain import reserve_domain_id
from glocal_ros.sim_contract import PHASE_EVAL
from node_common.runner import spinning_node
from learner_node.profiles import DEFAULT_PROFILE, PROFILES

TASKS = ("A0", "C3", "E2", "G3")  # from the prior's certain grasp to its usual miss: short and long episodes
POLICY = "prior"
SEED = 7
VARIANTS = ("floor", "via sim_node", "learner_node", "on the training envs")


@dataclass(frozen=True)
class EvalBenchRow:
    num_envs: int  # training envs of the sim
    eval_envs: int
    workers: int
    env_steps: int  # of one evaluation, via sim_node
    episodes: int  # counted episodes of one evaluation
    scores: tuple[tuple[int, ...], ...]  # via sim_node, then every learner_node round: successes per task
    rounds: tuple[tuple[float, ...], ...]  # seconds per evaluation (floor: per env_steps env steps), per variant

    def rate(self, variant: str) -> float:
        """Env steps/s of ``variant`` (median of its rounds)."""
        return self.env_steps / statistics.median(self.rounds[VARIANTS.index(variant)])

    @property
    def floor_ratio(self) -> float:
        return self.rate("learner_node") / self.rate("floor")


class _CountingSteps:
    """A ``BatchStepper`` that counts the env steps it forwards."""

    def __init__(self, envs):
        self.envs, self.env_steps = envs, 0

    def reset(self, *request):
        return self.envs.reset(*request)

    def step(self, actions, *request):
        self.env_steps += len(actions)
        return self.envs.step(actions, *request)


def _timed(work: Callable[[], object]) -> tuple[float, object]:
    start = time.perf_counter()
    result = work()
    return time.perf_counter() - start, result


def run_eval_bench(num_envs: int, eval_envs: int, episodes: int, rounds: int, profile: str = DEFAULT_PROFILE,
                   log: Callable[[str], None] = print) -> EvalBenchRow:
    from glocal_interfaces.srv import Evaluate

    from learner_node.evaluation import evaluate
    from learner_node.policies import PolicyRegistry
    from learner_node.policy_store import PolicyStore
    from learner_node.sim_client import SimClient
    from learner_node.training import Trainer
    from node_common import names
    from node_common.calls import call_checked
    from sim_node.grasp_env import GraspEnvConfig
    from sim_node.parallel import ProcessBatchedEnvs

    from glocal_ros.paths import objects_dir
    from learner_node.sac_settings import sac_algorithm

    sac_algorithm()  # one compute thread, as learner_node acts: the same numbers, so the same episodes
    workers = min(eval_envs, os.cpu_count() or 1)
    domain_id, lock = reserve_domain_id()
    work = Path(tempfile.mkdtemp(prefix="glocal-bench-eval-"))
    logs = work / "logs"
    learner_profile = PROFILES[profile]
    policies = PolicyRegistry(PolicyStore(work / "policies"), [PolicyStore(learner_profile.shipped_priors())])
    timeout = 60.0 + 0.5 * episodes * len(TASKS)
    stack = ExitStack()
    processes: list[NodeProcess] = []
    try:
        node = stack.enter_context(spinning_node("bench_eval", domain_id))
        env = isolated_environment(domain_id, logs)
        clients = {}
        for namespace, own_envs in (("/own", eval_envs), ("/shared", 0)):
            processes.append(NodeProcess("sim_node", logs, {"num_envs": num_envs, "eval_envs": own_envs,
                                                            "initial_task": TASKS[0]},
                                         env=env, extra_args=namespace_arguments(namespace)))
            processes.append(NodeProcess("learner_node", logs, {"policy_dir": str(work / namespace.strip("/")),
                                                                "learner_profile": profile},
                                         env=env, extra_args=namespace_arguments(namespace)))
            clients[namespace] = node.create_client(Evaluate, f"{namespace}/{names.LEARNER_EVALUATE}")
        sim = SimClient(node, namespace="/own")
        for client in (*clients.values(), sim):
            deadline = time.monotonic() + 120
            while not (client.ready() if client is sim else client.service_is_ready()):
                if not all(p.running for p in processes) or time.monotonic() > deadline:
                    raise RuntimeError(f"the bench's nodes did not start: see the logs in {logs}")
                time.sleep(0.1)
        policy = Trainer(sim, policies, work / "checkpoints", profile=learner_profile).evaluation_policy(
            POLICY, TASKS, SEED)
        floor_envs = stack.enter_context(closing(ProcessBatchedEnvs(
            eval_envs, workers, TASKS[0], str(objects_dir()), GraspEnvConfig())))
        request = Evaluate.Request(policy=POLICY, tasks=list(TASKS), episodes=episodes, seed=SEED)

        def via_sim_node():
            counting = _CountingSteps(sim)
            scores = evaluate(counting, policy, TASKS, episodes, policy_name=POLICY, seed=SEED)
            return counting.env_steps, [score.successes for score in scores]

        def through(namespace: str):
            response = call_checked(clients[namespace], request, timeout)
            return [score.successes for score in response.scores]

        for namespace in clients:  # the first request makes the evaluation envs and compiles the policy
            through(namespace)
        rng = np.random.default_rng(0)
        env_steps, expected_scores = via_sim_node()
        runs: list[list[float]] = [[] for _ in VARIANTS]
        scored = [tuple(expected_scores)]
        for round_index in range(rounds):
            seconds, (steps, scores) = _timed(via_sim_node)
            if (steps, scores) != (env_steps, expected_scores):
                raise RuntimeError(f"a seeded evaluation via sim_node changed: {steps} env steps and scores "
                                   f"{scores}, first {env_steps} and {expected_scores}")
            actions = rng.uniform(-1, 1, (-(-env_steps // eval_envs), eval_envs, 5)).astype(np.float32)
            floor_seconds, _ = _timed(lambda: [floor_envs.step(a, (), PHASE_EVAL) for a in actions])
            runs[0].append(floor_seconds * env_steps / actions.shape[0] / eval_envs)
            runs[1].append(seconds)
            for variant, namespace in (("learner_node", "/own"), ("on the training envs", "/shared")):
                seconds, scores = _timed(lambda: through(namespace))
                if namespace == "/own":
                    scored.append(tuple(scores))
                runs[VARIANTS.index(variant)].append(seconds)
            log(f"round {round_index + 1}/{rounds}: " + ", ".join(
                f"{variant} {env_steps / run[-1]:.0f} env steps/s" for variant, run in zip(VARIANTS, runs)))
        return EvalBenchRow(num_envs, eval_envs, workers, env_steps, episodes * len(TASKS), tuple(scored),
                            tuple(tuple(run) for run in runs))
    finally:
        stack.close()
        for process in reversed(processes):
            process.stop()
        lock.close()
        shutil.rmtree(work, ignore_errors=True)


def eval_bench_report(row: EvalBenchRow, command: str, rounds: int, profile: str) -> str:
    lines = [
        "# bench eval: evaluation through learner_node beside its floor",
        "",
        f"Command: `{command}`  ",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {sys.version.split()[0]}, {os.cpu_count()} CPU cores. "
        f"Load average at the end {os.getloadavg()[0]:.1f} (the machine is shared). Profile `{profile}`, policy "
        f"`{POLICY}` on {', '.join(TASKS)}, {row.episodes // len(TASKS)} episodes each, seed {SEED}: "
        f"{row.episodes} episodes, {row.env_steps} env steps per evaluation. sim_node: {row.num_envs} training "
        f"envs, {row.eval_envs} evaluation envs over {row.workers} workers. *floor*: {row.eval_envs} envs over "
        f"{row.workers} worker processes in the bench process, random actions. *on the training envs*: a sim_node "
        f"with `eval_envs:=0`, evaluating on its {row.num_envs} training envs. Median of {rounds} alternating "
        f"rounds.",
        "",
        "| variant | env steps/s | episodes/s | ratio to floor |",
        "| --- | ---: | ---: | ---: |",
    ]
    floor = row.rate("floor")
    for variant in VARIANTS:
        rate = row.rate(variant)
        episodes = "-" if variant == "floor" else f"{rate * row.episodes / row.env_steps:.1f}"
        lines.append(f"| {variant} | {rate:.0f} | {episodes} | {rate / floor:.2f} |")
    lines += ["", f"Scores ({', '.join(TASKS)}): via sim_node {list(row.scores[0])}; learner_node, round by round: "
              + "; ".join(str(list(scores)) for scores in row.scores[1:]), "",
              "Every round, env steps/s in order:", ""]
    for variant, run in zip(VARIANTS, row.rounds):
        lines.append(f"- {variant}: " + ", ".join(f"{row.env_steps / seconds:.0f}" for seconds in run))
    return "\n".join(lines) + "\n"
