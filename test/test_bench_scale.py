"""The scaling model (``glocal_ros.analysis.scale``) on a synthetic journal, and ``bench scale``'s refusals.

The journal is written by the real strategy over the learner double; durations are the model's, so the
virtual clock's answers can be worked out by hand. Nothing here is timed.
"""

import json

import pytest

from glocal_app.cli import build_parser
from glocal_ros.analysis.scale import (
    CallModel, RecordedRun, VirtualCalls, VirtualClock, entry_cost, read_recorded_run, schedule, simulate,
    with_pairs,
)
from glocal_ros.curriculum.journal import CallJournal
from glocal_ros.curriculum.run import Run
from glocal_ros.curriculum.strategies import run_strategy
from learner_double import SimulatedLearner
from test_curriculum import SHORT, config

MODEL = CallModel(train_call_s=2.0, evaluate_call_s=1.0, copy_call_s=0.5, step_s=0.01, eval_episode_s=0.1)


def recorded(tmp_path, strategy="glocal"):
    """A sequential run of the double, journaled; every goal's checks as the bag would count them: none."""
    run_config = config(strategy, **SHORT)
    path = tmp_path / "journal.jsonl"
    journal = CallJournal(path, run_config.journal_settings())
    run_strategy(Run(run_config, SimulatedLearner(seed=1, lockstep_envs=2), journal=journal))
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    return RecordedRun(tmp_path, run_config, lines[0]["config"], lines[1:], 1, [0, 1], {})


@pytest.mark.parametrize("strategy", ["glocal", "random"])
def test_one_pair_takes_the_sum_of_the_recorded_calls(tmp_path, strategy):
    run = recorded(tmp_path, strategy)
    expected = sum(MODEL.seconds(entry_cost(entry, {})) for entry in run.entries)
    prediction = simulate(run.config, run, MODEL, 1, 50)
    assert prediction.seconds == pytest.approx(expected)
    assert prediction.total_steps == sum(e["answer"]["steps_used"] for e in run.entries if e["call"] == "train")


def test_more_pairs_are_never_slower_and_overlap_the_locals(tmp_path):
    run = recorded(tmp_path)
    seconds = [simulate(with_pairs(run.config, k), run, MODEL, k, 50).seconds for k in (1, 2, 4)]
    assert seconds[1] < seconds[0] and seconds[2] <= seconds[1]


class Timed:
    def __init__(self, seconds):
        self.last_seconds = seconds


def test_the_virtual_clock_ends_calls_earliest_first_from_when_each_started():
    clock = VirtualClock()
    calls = VirtualCalls(clock)
    calls.start(0, Timed(3.0), "a", lambda learner: "A")
    calls.start(1, Timed(2.0), "b", lambda learner: "B")
    assert calls.next_done() == (1, "b", "B") and clock.now == 2.0
    calls.start(1, Timed(4.0), "c", lambda learner: "C")  # starts at 2, ends at 6
    assert calls.next_done() == (0, "a", "A") and clock.now == 3.0
    assert calls.next_done() == (1, "c", "C") and clock.now == 6.0


def test_a_grid_goes_longest_first_to_the_slot_free_first():
    assert schedule([3, 2, 4], 1) == 9
    assert schedule([3, 2, 4], 2) == 5  # 4 | 3 + 2
    assert schedule([3, 2, 4], 8) == 4
    with pytest.raises(ValueError, match="at least 1"):
        schedule([1], 0)


def test_fewer_than_one_pair_is_refused(tmp_path):
    run = recorded(tmp_path)
    with pytest.raises(ValueError, match="pairs must be at least 1"):
        simulate(run.config, run, MODEL, 0, 50)


def test_a_directory_without_journal_or_bag_is_refused(tmp_path):
    with pytest.raises(ValueError, match="no curriculum/journal.jsonl"):
        read_recorded_run(tmp_path)
    recorded(tmp_path)
    (tmp_path / "curriculum").mkdir()
    (tmp_path / "journal.jsonl").rename(tmp_path / "curriculum" / "journal.jsonl")
    with pytest.raises(ValueError, match="no bag/"):
        read_recorded_run(tmp_path)


def bench_scale(*arguments):
    args = build_parser().parse_args(["bench", "scale", *map(str, arguments)])
    return args.func(args)


def test_the_command_refuses_bad_input_before_writing(tmp_path, capsys):
    out = tmp_path / "scale.md"
    assert bench_scale(tmp_path / "nowhere", "--out", out) != 0
    assert "not a directory" in capsys.readouterr().err
    assert bench_scale(tmp_path, "--out", out) != 0
    assert "no curriculum/journal.jsonl" in capsys.readouterr().err
    assert bench_scale(tmp_path, "--pairs", "0", "--out", out) != 0
    assert "--pairs must be whole numbers of at least 1" in capsys.readouterr().err
    assert not out.exists()
