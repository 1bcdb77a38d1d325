"""A namespaced graph works end to end: `glocal-ros launch --namespace robot1` on a ROS_DOMAIN_ID of the user's.

One smoke run, as the launch tests run it, with ``--namespace robot1
--use-sim-time`` and ``ROS_DOMAIN_ID`` set in its environment. It must:
run on that domain (a node of this test on it hears the run's curriculum
state under /robot1 while it runs, and nothing at the root); take its preset
under the namespace (the presets are keyed ``/**/NODE``: budget, tasks and
envs of smoke, else the run would not end); record every topic of
``glocal_ros.topics.RECORDED_TOPICS`` under ``/robot1/``, and nothing
outside it; give sim_node the sim's own clock (its stamps are sim time, not
wall-clock); and report the run.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from glocal_interfaces.msg import CurriculumState, EpisodeRecord
from rosbags.highlevel import AnyReader

from conftest import REPO, smoke_tasks
from glocal_ros.domain import reserve_domain_id
from glocal_ros.recording import episode_sequence, graph_typestore
from glocal_ros.sim_contract import DEFAULT_EVAL_ENVS
from glocal_ros.topics import RECORDED_TOPICS
from node_common import qos

NAMESPACE = "/robot1"
RUN_SEC = 420  # a smoke run takes about a minute on an idle machine
#: A sim stamp is seconds of sim time since the sim started; wall-clock stamps are since 1970.
WALL_CLOCK_SEC = 1e9


class Listener:
    """A node of the test on ``domain_id``, counting curriculum states under the namespace and at the root."""

    def __init__(self, domain_id: int):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node("namespace_test_listener", context=self.context)
        self.heard = {NAMESPACE: [], "": []}
        for prefix, states in self.heard.items():
            self.node.create_subscription(CurriculumState, f"{prefix}/glocal/curriculum_state", states.append,
                                          qos.LATCHED)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self.stop.is_set():
            self.executor.spin_once(timeout_sec=0.1)

    def close(self) -> None:
        import rclpy

        self.stop.set()
        self.thread.join(5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def bag_messages(bag) -> dict[str, list]:
    with AnyReader([bag], default_typestore=graph_typestore()) as reader:
        messages: dict[str, list] = {c.topic: [] for c in reader.connections}
        for connection, _, raw in reader.messages():
            messages[connection.topic].append(reader.deserialize(raw, connection.msgtype))
    return messages


def log_times(bag) -> list[float]:
    """Every message's log time (the recorder's clock when it received it), in seconds."""
    with AnyReader([bag], default_typestore=graph_typestore()) as reader:
        return [log_time * 1e-9 for _, log_time, _ in reader.messages()]


def curves_dir(run_dir: Path) -> Path:
    return run_dir.parent / "curves"


@pytest.fixture(scope="module")
def namespaced_run(tmp_path_factory):
    """The smoke run under /robot1 on a domain id reserved here and set as the user would set it, its training
    curves beside its run directory (``curves_dir``)."""
    run_dir = tmp_path_factory.mktemp("namespaced") / "run"
    # Held by the test for the whole run: no other run or test on this machine takes the domain.
    domain_id, lock = reserve_domain_id()
    listener = Listener(domain_id)
    try:
        command = [sys.executable, "-m", "glocal_app.cli", "launch", "--preset", "smoke", "--seed", "2",
                   "--namespace", "robot1", "--use-sim-time", "--out", str(run_dir),
                   "--tensorboard", str(curves_dir(run_dir))]
        result = subprocess.run(command, capture_output=True, text=True, timeout=RUN_SEC, cwd=REPO,
                                env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)})
    finally:
        listener.close()
        lock.close()
    return run_dir, domain_id, result, listener.heard


def test_the_run_uses_the_users_domain_and_ends(namespaced_run):
    run_dir, domain_id, result, heard = namespaced_run
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"namespace {NAMESPACE} on ROS_DOMAIN_ID {domain_id} (from the environment)" in result.stdout
    # The test holds the domain, as another run would: the launch says the two graphs meet.
    assert "another run on this machine holds" in result.stdout
    assert heard[NAMESPACE], "no curriculum state under /robot1 on the user's domain"
    assert heard[NAMESPACE][-1].status == CurriculumState.STATUS_FINISHED
    assert heard[""] == [], "a namespaced graph publishes nothing at the root"
    assert (run_dir / "report" / "report.md").is_file(), result.stdout


def test_every_recorded_topic_is_in_the_bag_under_the_namespace(namespaced_run):
    run_dir, _, result, _ = namespaced_run
    assert result.returncode == 0, result.stdout + result.stderr
    messages = bag_messages(run_dir / "bag")
    expected = {NAMESPACE + spec.name for spec in RECORDED_TOPICS}
    missing = sorted(topic for topic in expected if not messages.get(topic))
    assert missing == [], f"no message on {missing}; the bag has {sorted(messages)}"
    assert sorted(set(messages) - expected) == [], "a topic outside the namespace or the table"

    # The smoke preset reached every node under the namespace.
    final = messages[f"{NAMESPACE}/glocal/curriculum_state"][-1]
    assert final.status == CurriculumState.STATUS_FINISHED and final.step_budget == 300
    assert final.run_id == "glocal-seed2"
    episodes = messages[f"{NAMESPACE}/glocal/episodes"]
    training = {e.env_index for e in episodes if e.phase == EpisodeRecord.PHASE_TRAIN}
    evaluation = {e.env_index for e in episodes if e.phase == EpisodeRecord.PHASE_EVAL}
    assert training == {0, 1}, "num_envs 2"
    assert evaluation and evaluation <= set(range(2, 2 + DEFAULT_EVAL_ENVS)), "evaluation envs numbered after them"
    assert {e.task for e in episodes} <= set(smoke_tasks())
    check = episode_sequence(run_dir / "bag", f"{NAMESPACE}/glocal/episodes")
    assert check.ok and check.first == 0, check.summary()


def test_use_sim_time_puts_the_sim_on_its_own_clock(namespaced_run):
    run_dir, _, result, _ = namespaced_run
    assert result.returncode == 0, result.stdout + result.stderr
    messages = bag_messages(run_dir / "bag")
    clock = [m.clock.sec + m.clock.nanosec * 1e-9 for m in messages[f"{NAMESPACE}/clock"]]
    assert clock and clock[-1] > 0
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in messages[f"{NAMESPACE}/joint_states"]]
    assert stamps and max(stamps) < WALL_CLOCK_SEC, "joint_states stamped with wall-clock time, not the sim's"
    assert max(stamps) <= clock[-1]
    # The recorder is on the same clock: it hears /robot1/clock (remapped from the /clock that rclpy's
    # time source subscribes to), so it records sim time; on /clock it would read 0 throughout.
    recorded = log_times(run_dir / "bag")
    assert 0 < max(recorded) < WALL_CLOCK_SEC


def test_the_runs_training_curves_are_the_bags_numbers(namespaced_run):
    """``--tensorboard DIR`` as ``tensorboard --logdir`` lists it: a run per Train goal, whose progress and
    evaluation scalars are those of the goal's messages in the bag."""
    from tensorboard.backend.event_processing.event_multiplexer import EventMultiplexer

    run_dir, _, result, _ = namespaced_run
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"--logdir {curves_dir(run_dir)}" in result.stdout, "the launch says how to open them"
    assert not (run_dir / "tensorboard").exists()
    curves = EventMultiplexer().AddRunsFromDirectory(str(curves_dir(run_dir)))
    curves.Reload()
    messages = bag_messages(run_dir / "bag")
    goals = {a.output_policy for a in messages[f"{NAMESPACE}/glocal/task_assignment"] if a.output_policy}
    assert goals and set(curves.Runs()) == goals

    def scalars(goal: str, tag: str) -> list[tuple[int, float]]:
        tags = curves.Runs()[goal]["scalars"]
        return [(event.step, event.value) for event in curves.Scalars(goal, tag)] if tag in tags else []

    progress = messages[f"{NAMESPACE}/glocal/training_progress"]
    assert progress, "no goal reported progress"
    for goal in goals:
        reports = [m for m in progress if m.output_policy == goal]
        assert scalars(goal, "time/fps") == [(m.goal_steps, m.env_steps_per_second) for m in reports]
        assert scalars(goal, "rollout/success_rate") == [(m.goal_steps, m.recent_success_rate) for m in reports]
        assert scalars(goal, "train/critic_loss") == [(m.goal_steps, m.critic_loss) for m in reports
                                                      if not math.isnan(m.critic_loss)]
        scores = [score.successes for m in messages[f"{NAMESPACE}/glocal/evaluations"]
                  if m.policy == goal and m.purpose == "train" for score in m.scores]
        assert [value for _, value in scalars(goal, "eval/successes")] == scores
