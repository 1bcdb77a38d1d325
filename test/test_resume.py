"""A run resumed after a kill asks and hears what the uninterrupted run did, call for call.

Every learner call of a run carries a seed derived from the run seed and the
call's place (``glocal_ros.curriculum.journal``), so the journal of a run
whose curriculum node or learner was killed and started again must equal,
line for line, the journal of the same run left alone: every score, every
training episode's length, return and success. One sim serves all three runs
one after another, so a call's outcome must not depend on what the sim did
before it either. The learners checkpoint every 20 steps, so that the killed
learner's goal resumes from a checkpoint (a cut in every run alike, see
``learner_node.training``).
"""

import json
import signal

import pytest

from conftest import REPO, SMOKE, journal_lines, wait_for_clean_exit, wait_until
from glocal_app.processes import NodeProcess

SEED = 7
RUN_SEC = 300  # a smoke run takes under a minute on an idle machine
CHECKPOINT_INTERVAL = 20


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    process = NodeProcess("sim_node", tmp_path_factory.mktemp("sim"), params_file=SMOKE, cwd=REPO)
    yield process
    process.stop()


def learner(folder, **params) -> NodeProcess:
    params = {"policy_dir": str(folder / "policies"), "checkpoint_interval": CHECKPOINT_INTERVAL, **params}
    return NodeProcess("learner_node", folder, params, params_file=SMOKE, cwd=REPO)


def curriculum(folder) -> NodeProcess:
    params = {"strategy": "glocal", "seed": SEED, "state_dir": str(folder / "state"), "learner_timeout_sec": 120.0}
    return NodeProcess("curriculum_node", folder, params, params_file=SMOKE, cwd=REPO)


def journal(folder) -> list[str]:
    return journal_lines(folder / "state")


def finish(node: NodeProcess, others) -> None:
    wait_for_clean_exit(node, RUN_SEC, others)


@pytest.fixture(scope="module")
def uninterrupted(sim, tmp_path_factory) -> list[str]:
    folder = tmp_path_factory.mktemp("uninterrupted")
    own_learner = learner(folder)
    try:
        finish(curriculum(folder), [sim, own_learner])
    finally:
        own_learner.stop()
    lines = journal(folder)
    assert sum('"call": "train"' in line for line in lines) >= 3, lines
    return lines


def assert_same_run(resumed: list[str], uninterrupted: list[str]) -> None:
    assert len(resumed) == len(uninterrupted)
    for number, (line, expected) in enumerate(zip(resumed, uninterrupted)):
        assert json.loads(line) == json.loads(expected), f"journal entry {number} differs"


def test_a_run_whose_curriculum_node_was_killed_resumes_call_for_call(sim, uninterrupted, tmp_path):
    own_learner = learner(tmp_path)
    try:
        first = curriculum(tmp_path)
        # Killed after the header, the first evaluation and a goal or two: most likely in a goal.
        wait_until(lambda: len(journal(tmp_path)) >= 4, RUN_SEC, "a journal with three answers",
                   processes=[sim, own_learner, first])
        first.process.send_signal(signal.SIGKILL)
        first.process.wait()
        answered = journal(tmp_path)
        second = curriculum(tmp_path)
        finish(second, [sim, own_learner])
    finally:
        own_learner.stop()
    assert "resuming glocal-seed7" in second.log()
    assert f"replayed {len(answered) - 1} answered calls in" in second.log()  # also reported on diagnostics
    resumed = journal(tmp_path)
    assert resumed[:len(answered)] == answered, "the journal was continued, not rewritten"
    assert_same_run(resumed, uninterrupted)


def test_a_run_whose_learner_was_killed_mid_goal_resumes_call_for_call(sim, uninterrupted, tmp_path):
    first_learner = learner(tmp_path)
    node = curriculum(tmp_path)
    second_learner = None

    def goal_with_a_checkpoint() -> bool:  # a goal's checkpoint.json lives from its first checkpoint to its end
        return any((tmp_path / "policies" / ".checkpoints").glob("*/checkpoint.json"))

    try:
        wait_until(lambda: len(journal(tmp_path)) >= 4, RUN_SEC, "a journal with three answers",
                   processes=[sim, first_learner, node])
        wait_until(goal_with_a_checkpoint, RUN_SEC, "a goal with a checkpoint", poll=0.01,
                   processes=[sim, first_learner, node])
        first_learner.process.send_signal(signal.SIGKILL)
        first_learner.process.wait()
        second_learner = learner(tmp_path)
        finish(node, [sim, second_learner])
    finally:
        for process in (first_learner, second_learner):
            if process is not None:
                process.stop()
    assert "sending the goal again" in node.log(), node.log()
    assert "resumed from a checkpoint" in second_learner.log(), second_learner.log()
    assert_same_run(journal(tmp_path), uninterrupted)
