"""GloCAL over two sim/learner pairs (/pair0, /pair1, one policy store) survives kill -9 of a pair or of itself.

Real nodes, each pair's sim and learner started as processes in its namespace
as a user starts them (README, "Several pairs"), the curriculum node with
``parallel_locals`` over both. Goals are long enough to be killed in (400
steps, checkpointed every 40), and every call is seeded by its key, so a
call asked with the same arguments gets the same answer on either pair and
after a resume from a checkpoint. What depends on timing with two pairs (which
tasks are in flight when the next iteration evaluates, a goal clipped to the
steps left) can change the arguments of later calls, so runs are compared
where they must agree: the learned set, and the answer of every key that
both asked with the same arguments.

- The pair training a goal killed mid-goal: its goal goes to the other pair once the pair has
  been out of the graph for ``learner_away_sec`` (DDS notices a kill after
  its 20 s lease) and resumes there from its checkpoint; the pair started
  again rejoins the run. (A goal resent to the same learner after its restart
  is test_train.py's; a pool waiting for a learner to come back,
  test_parallel_locals.py's.)
- The curriculum node killed with a goal in flight: started again
  with the same state directory, it waits for those goals to end, replays its
  journal and sends the calls that were in flight again, which the learners
  answer from the goals' kept outcomes instead of training them twice.
"""

import json
import signal

import pytest
from glocal_interfaces.msg import TrainingProgress

from conftest import REPO, SMOKE, journal_lines, wait_for_clean_exit, wait_until
from glocal_app.processes import NodeProcess, namespace_arguments
from node_common import names, qos

PAIRS = ("/pair0", "/pair1")
CHECKPOINT_INTERVAL = 40
#: The smoke preset's tasks and T, with goals long enough to be killed in and a budget for about four of them.
RUN = {"strategy": "glocal", "seed": 0, "parallel_locals": True, "learner_namespaces": "pair0,pair1",
       "task_step_budget": 400, "step_budget": 1600, "eval_interval": 200, "milestone_interval": 400,
       "learner_timeout_sec": 120.0}
RUN_SEC = 420  # a run takes about a minute on an idle machine; the slack is for a loaded one and the kills
START_SEC = 180


class Pairs:
    """Sim/learner pairs in ``PAIRS``, every learner on the store ``folder/policies``; ``kill`` as kill -9 does."""

    def __init__(self, folder):
        self.folder, self.store = folder, folder / "policies"
        self.running: dict[str, list[NodeProcess]] = {}
        self.every: list[NodeProcess] = []

    def start(self, namespace: str) -> None:
        extra = namespace_arguments(namespace)
        learner_params = {"policy_dir": str(self.store), "checkpoint_interval": CHECKPOINT_INTERVAL}
        self.running[namespace] = [
            NodeProcess("sim_node", self.folder, params_file=SMOKE, cwd=REPO, extra_args=extra),
            NodeProcess("learner_node", self.folder, learner_params, params_file=SMOKE, cwd=REPO, extra_args=extra)]
        self.every += self.running[namespace]

    def kill(self, namespace: str) -> None:
        for process in self.running.pop(namespace):
            process.process.send_signal(signal.SIGKILL)
            process.process.wait()

    def processes(self) -> list[NodeProcess]:
        return [process for pair in self.running.values() for process in pair]

    def learner_logs(self) -> str:
        return "\n".join(process.log() for process in self.every if process.node == "learner_node")

    def stop(self) -> None:
        for pair in self.running.values():
            for process in reversed(pair):
                process.stop()


@pytest.fixture
def pairs(tmp_path):
    both = Pairs(tmp_path)
    for namespace in PAIRS:
        both.start(namespace)
    yield both
    both.stop()


@pytest.fixture
def progress(ros_node):
    """Every TrainingProgress of each pair, as it comes: {namespace: [message, ...]}."""
    heard = {namespace: [] for namespace in PAIRS}
    for namespace in PAIRS:
        ros_node.create_subscription(TrainingProgress, f"{namespace}/{names.TRAINING_PROGRESS}",
                                     heard[namespace].append, qos.EVENTS)
    return heard


def curriculum(folder, **params) -> NodeProcess:
    return NodeProcess("curriculum_node", folder, {**RUN, "state_dir": str(folder / "state"), **params},
                       params_file=SMOKE, cwd=REPO)


def journal(folder) -> list[dict]:
    return [json.loads(line) for line in journal_lines(folder / "state")[1:]]


def answered_policies(folder) -> set[str]:
    return {entry["arguments"]["output_policy"] for entry in journal(folder) if entry["call"] == "train"}


def finish(node: NodeProcess, pairs: Pairs) -> None:
    wait_for_clean_exit(node, RUN_SEC, pairs.processes())


def final_state(folder) -> dict:
    return json.loads((folder / "state" / "state.json").read_text())


def goal_in_flight(heard: list, folder, pairs: Pairs):
    """The policy a pair is training past its first checkpoint and before three quarters of its budget, not
    answered yet."""
    if not heard:
        return None
    latest = heard[-1]
    checkpoint = pairs.store / ".checkpoints" / latest.output_policy / "checkpoint.json"
    if (CHECKPOINT_INTERVAL <= latest.goal_steps <= latest.step_budget * 3 // 4 and checkpoint.is_file()
            and latest.output_policy not in answered_policies(folder)):
        return latest.output_policy
    return None


def assert_every_call_answered_once(folder, uninterrupted: list[dict]) -> None:
    keys = [entry["key"] for entry in journal(folder)]
    assert len(keys) == len(set(keys)), f"a call answered twice: {keys}"
    alone = {entry["key"]: entry for entry in uninterrupted}
    same = [entry for entry in journal(folder)
            if entry["key"] in alone and entry["arguments"] == alone[entry["key"]]["arguments"]]
    assert len(same) >= 3, "the runs share their first calls at least"
    for entry in same:
        assert entry["answer"] == alone[entry["key"]]["answer"], f"{entry['key']} answered otherwise"


def resumed_at(logs: str, policy: str) -> list[int]:
    """The checkpoint steps the learners' logs say ``policy``'s goal resumed from."""
    marker = f"{policy}: "
    steps = []
    for line in logs.splitlines():
        if marker in line and "resumed from a checkpoint at step " in line:
            steps.append(int(line.rsplit("at step ", 1)[1].rstrip(")")))
    return steps


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> tuple[list[dict], dict]:
    """The journal and final state of the run left alone."""
    folder = tmp_path_factory.mktemp("uninterrupted")
    both = Pairs(folder)
    try:
        for namespace in PAIRS:
            both.start(namespace)
        finish(curriculum(folder), both)
    finally:
        both.stop()
    entries = journal(folder)
    assert {entry["learner"] for entry in entries} == {0, 1}, "both pairs had calls"
    return entries, final_state(folder)


def test_a_goal_whose_pair_was_killed_resumes_on_the_other_pair_and_the_pair_comes_back(
        pairs, progress, uninterrupted, tmp_path):
    """The pair training a goal killed mid-goal and away past ``learner_away_sec`` (3 s, after DDS's lease): its
    goal resumes on the other pair from its checkpoint; the killed pair started again then rejoins a run that
    ends as the uninterrupted one. Which pair trains a goal first depends on the run's scores and timing (the
    scheduler gives a call to the first idle learner), so the test kills whichever does."""
    node = curriculum(tmp_path, learner_away_sec=3.0)

    def pair_in_flight():
        for namespace in PAIRS:
            policy = goal_in_flight(progress[namespace], tmp_path, pairs)
            if policy:
                return namespace, policy
        return None

    victim, killed = wait_until(pair_in_flight, RUN_SEC, "a pair training a goal past its first checkpoint",
                                poll=0.01, processes=pairs.processes() + [node])
    survivor = next(namespace for namespace in PAIRS if namespace != victim)
    pairs.kill(victim)
    heard_before = len(progress[survivor])
    wait_until(lambda: "left the graph and was not back within 3 s" in node.log(), RUN_SEC,
               "the killed pair's goal sent to the other pair", processes=pairs.processes() + [node])
    pairs.start(victim)
    finish(node, pairs)

    assert_every_call_answered_once(tmp_path, uninterrupted[0])
    entry = next(e for e in journal(tmp_path) if e["call"] == "train" and e["arguments"]["output_policy"] == killed)
    assert entry["learner"] == PAIRS.index(survivor), "answered by the pair that stayed"
    steps = resumed_at(pairs.learner_logs(), killed)
    assert steps and steps[0] >= CHECKPOINT_INTERVAL, pairs.learner_logs()
    after = [m.goal_steps for m in progress[survivor][heard_before:] if m.output_policy == killed]
    assert after and min(after) > steps[0], "the goal went on from its checkpoint, not from step 0"
    assert sorted(final_state(tmp_path)["learned_tasks"]) == sorted(uninterrupted[1]["learned_tasks"])


def test_a_curriculum_node_killed_with_goals_in_flight_resumes_the_run(pairs, progress, uninterrupted, tmp_path):
    """Killed while a pair trains a goal (both pairs train at once only for a few seconds of this run, so one
    goal in flight is what the test waits for; the other pair may be evaluating). Progress comes once a second,
    and a goal learned at its first check ends at half its budget: one seen below half is still running."""
    first = curriculum(tmp_path)

    def goals_in_flight():
        latest = [progress[namespace][-1] for namespace in PAIRS if progress[namespace]]
        goals = {m.output_policy for m in latest if 0 < m.goal_steps < m.step_budget // 2}
        return goals - answered_policies(tmp_path) or None

    in_flight = wait_until(goals_in_flight, RUN_SEC, "a goal in flight", poll=0.01,
                           processes=pairs.processes() + [first])
    first.process.send_signal(signal.SIGKILL)
    first.process.wait()
    answered = (tmp_path / "state" / "journal.jsonl").read_text()
    assert not in_flight & answered_policies(tmp_path), "no goal in flight was answered before the kill"
    second = curriculum(tmp_path)
    finish(second, pairs)

    assert "resuming glocal-seed0" in second.log()
    assert (tmp_path / "state" / "journal.jsonl").read_text().startswith(answered), "continued, not rewritten"
    assert_every_call_answered_once(tmp_path, uninterrupted[0])
    assert in_flight <= answered_policies(tmp_path)
    logs = pairs.learner_logs()
    for policy in in_flight:  # ended by the learner that had it, then answered from its kept outcome
        assert f"{policy}: finished before, not trained again" in logs, logs
        assert not resumed_at(logs, policy), f"{policy} ran a second time"
    assert sorted(final_state(tmp_path)["learned_tasks"]) == sorted(uninterrupted[1]["learned_tasks"])
