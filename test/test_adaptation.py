"""Adapting to a novel object (issue 46): which of a run's policies are candidates, which one is chosen, and the
goal that fine-tunes it, against the learner double (where the premise, a policy that scores more on the new
object, would otherwise be a learning outcome). `glocal-ros adapt` through the graph is in test_launch."""

from __future__ import annotations

import numpy as np
import pytest

from glocal_ros.adaptation import AdaptSettings, Candidate, NoGlobalPolicyError, adapt, choose, run_candidates
from glocal_ros.tasks import UnknownTaskError, task_index
from learner_double import SimulatedLearner

STORED = {"glocal-seed3.G2": "C3", "glocal-seed3.G1": "A1", "glocal-seed3.L1_0": "B2", "glocal-seed3.G10": "E5",
          "glocal-seed3.adapt-mug": "A1", "glocal-seed30.G1": "G6", "random-seed3.policy": "D0"}


def test_the_candidates_are_the_runs_global_policies_by_iteration_its_last_policy_and_the_prior():
    candidates = run_candidates("glocal-seed3", "glocal", STORED, last_policy="glocal-seed3.L1_0")
    assert candidates == [Candidate("glocal-seed3.G1", ("global 1",), "A1"),
                          Candidate("glocal-seed3.G2", ("global 2",), "C3"),
                          Candidate("glocal-seed3.G10", ("global 10",), "E5"),
                          Candidate("glocal-seed3.L1_0", ("last",), "B2"),
                          Candidate("prior", ("prior",), "A0")]
    listed_once = run_candidates("glocal-seed3", "glocal", STORED, last_policy="glocal-seed3.G10")
    assert [c.roles for c in listed_once] == [("global 1",), ("global 2",), ("global 10", "last"), ("prior",)]


def test_a_run_without_a_global_policy_or_whose_last_policy_is_gone_is_refused():
    with pytest.raises(NoGlobalPolicyError, match="strategy random trains no global task"):
        run_candidates("random-seed3", "random", {**STORED, "random-seed3.G3": "G3"}, last_policy="random-seed3.G3")
    with pytest.raises(NoGlobalPolicyError, match="glocal-seed4 holds no global policy"):
        run_candidates("glocal-seed4", "glocal", STORED, last_policy="")
    with pytest.raises(ValueError, match="last policy 'glocal-seed3.L9_0' is not in its store"):
        run_candidates("glocal-seed3", "glocal", STORED, last_policy="glocal-seed3.L9_0")
    with pytest.raises(UnknownTaskError):
        run_candidates("glocal-seed3", "glocal", {**STORED, "glocal-seed3.G3": ""}, last_policy="")


def test_the_best_score_is_chosen_and_a_tie_goes_to_the_earlier_candidate():
    first, second, prior = (Candidate(name, (), "A0") for name in ("g1", "g2", "prior"))
    assert choose([(first, 3.0), (second, 7.0), (prior, 5.0)]) == second
    assert choose([(first, 7.0), (second, 7.0), (prior, 7.0)]) == first
    with pytest.raises(ValueError):
        choose([])


def test_every_candidate_is_scored_on_the_same_episodes_under_its_bit_and_the_best_fine_tuned_under_its_own():
    learner = SimulatedLearner(seed=1)
    # The double has no shapes: the novel object is, to it, the task whose bit it borrows. G1 has never seen
    # its task (the object is hard for it); G2 knows its own well, as a global policy knows its global task.
    learner.policies["run.G1"] = np.full(49, 0.02)
    learner.policies["run.G2"] = np.full(49, 0.02)
    learner.policies["run.G2"][task_index("E2")] = 0.6
    candidates = [Candidate("run.G1", ("global 1",), "B1"), Candidate("run.G2", ("global 2", "last"), "E2"),
                  Candidate("prior", ("prior",), "A0")]
    learner.policies["prior"][task_index("A0")] = 0.3
    settings = AdaptSettings(step_budget=20_000, threshold=15.0, eval_episodes=20, eval_interval=1_000, seed=4)
    adaptation = adapt(learner, "mug", candidates, "run.adapt-mug", settings)

    evaluations = [call for kind, call in learner.calls if kind == "evaluate"]
    assert evaluations == [("run.G1", ("mug@B1",)), ("run.G2", ("mug@E2",)), ("prior", ("mug@A0",))]
    assert [score for _, score in adaptation.scores][0] < adaptation.scores[1][1]
    assert adaptation.chosen == candidates[1] and adaptation.task == "mug@E2"
    (goal,) = [call for kind, call in learner.calls if kind == "train"]
    assert (goal.task, goal.initial_policy, goal.output_policy) == ("mug@E2", "run.G2", "run.adapt-mug")
    assert goal.stop_when_learned and goal.threshold == 15.0 and goal.eval_episodes == 20
    assert goal.step_budget == 20_000 and goal.eval_interval == 1_000
    assert adaptation.learned and 0 < adaptation.steps_to_b <= 20_000 and "run.adapt-mug" in learner.policies
    assert adaptation.to_dict()["candidates"][1] == {"policy": "run.G2", "roles": ("global 2", "last"),
                                                     "proxy": "E2", "score": adaptation.scores[1][1]}

    again = SimulatedLearner(seed=99)  # the same seed gives the same episodes, whatever the learner's own stream
    again.policies.update({name: learner.policies[name] for name in ("run.G1", "run.G2", "prior")})
    assert adapt(again, "mug", candidates, "run.adapt-mug", settings).scores == adaptation.scores


def test_bad_settings_and_names_are_refused_before_any_call():
    with pytest.raises(ValueError, match="step_budget >= 1"):
        AdaptSettings(step_budget=0, threshold=1.0, eval_episodes=2, eval_interval=0)
    with pytest.raises(ValueError, match="seed must be in 0..2147483647"):
        AdaptSettings(step_budget=10, threshold=1.0, eval_episodes=2, eval_interval=0, seed=-1)
    learner = SimulatedLearner()
    with pytest.raises(UnknownTaskError, match="collides with grid task C4"):
        adapt(learner, "c4", [Candidate("prior", ("prior",), "A0")], "x", AdaptSettings(10, 1.0, 2, 0))
    assert learner.calls == []


def test_bench_fewshot_takes_objects_from_every_third_of_the_lifting_pose_shares(tmp_path):
    from glocal_app.benches.fewshot import THIRDS, novel_objects
    from glocal_ros.objects import ObjectSetMetadata
    from glocal_ros.paths import objects_dir
    from glocal_ros.tasks import check_novel_name

    chosen = novel_objects(objects_dir(), per_third=3)
    shares = sorted(o.lifting_pose_share for o in ObjectSetMetadata.load(objects_dir()).objects.values())
    assert [o.third for o in chosen] == [third for third in THIRDS for _ in range(3)]
    assert [o.lifting_pose_share for o in chosen] == sorted(o.lifting_pose_share for o in chosen)
    assert chosen[0].lifting_pose_share <= shares[16] <= chosen[3].lifting_pose_share  # thirds of 49: 16, 17, 16
    assert all(check_novel_name(o.name) and (o.source / "model.urdf").is_file() for o in chosen)
    metadata = ObjectSetMetadata.load(objects_dir())
    metadata.objects["C4"].lifting_pose_share = None
    metadata.save(tmp_path)
    with pytest.raises(ValueError, match="no lifting-pose share for C4"):
        novel_objects(tmp_path)
    with pytest.raises(ValueError, match="need 1 to 16"):
        novel_objects(objects_dir(), per_third=17)


def test_bench_fewshot_refuses_objects_of_the_committed_set_before_any_goal():
    from glocal_app.benches.fewshot import run_fewshot_bench
    from glocal_app.benches.transfer import TransferSettings
    from glocal_ros.paths import objects_dir

    with pytest.raises(ValueError, match=r"not novel, objects of the committed set: ([A-G]\d) \(\1\)"):
        run_fewshot_bench([], objects_dir(), [0], TransferSettings(step_budget=40, eval_interval=20,
                                                                     eval_episodes=2, num_envs=2), per_third=1)
