"""`glocal-ros run`, `evaluate`, `collect-experience` and `policy import` as a user types them."""

import json
import shutil
import signal
import subprocess
import sys

import numpy as np

from conftest import REPO, wait_until

GLOCAL_ROS = [sys.executable, "-m", "glocal_app.cli"]


def run_cli(*args, timeout=120):
    return subprocess.run([*GLOCAL_ROS, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO)


def test_run_starts_a_node_that_the_graph_sees(start_node, ros_node):
    sim = start_node("sim_node", num_envs=1)
    wait_until(lambda: "sim_node" in ros_node.get_node_names(), 60, "sim_node on the graph", processes=[sim])
    assert sim.stop(signal.SIGINT) == 0, sim.log()


def test_run_refuses_an_unknown_node():
    result = run_cli("run", "no_such_node")
    assert result.returncode == 2 and "invalid choice" in result.stderr


def test_evaluate_prints_json_scores(start_node, ros_node):
    start_node("sim_node", num_envs=2, max_steps=8)
    start_node("learner_node")
    result = run_cli("evaluate", "--policy", "random", "--tasks", "A0,C3", "--episodes", "2", "--json")
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(scores) == {"A0", "C3"} and all(0 <= v <= 2 for v in scores.values())


def test_evaluate_reports_bad_input_without_a_traceback():
    result = run_cli("evaluate", "--policy", "random", "--tasks", "A0,Z1")
    assert result.returncode == 2
    assert "unknown task 'Z1'" in result.stderr and "Traceback" not in result.stderr


def test_collect_experience_gives_a_stored_policy_transitions_of_it_acting_on_its_task(tmp_path):
    from learner_node.policy_store import PolicyStore

    result = run_cli("collect-experience", "prior", "--out", str(tmp_path), "--transitions", "60", "--seed", "4")
    assert result.returncode == 0, result.stderr
    assert "prior: 60 transitions on A0" in result.stdout
    store, shipped = PolicyStore(tmp_path), PolicyStore(REPO / "assets" / "priors")
    assert len(store.experience("prior")["observations"]) == 60
    assert (tmp_path / "prior" / store.record("prior").model_file).read_bytes() == shipped.model_path(
        "prior").read_bytes(), "the model is the shipped one, unchanged"


def test_collect_experience_refuses_bad_input_without_a_traceback(tmp_path):
    from learner_node.policy_store import PolicyStore

    adapted = PolicyStore(tmp_path / "adapted")  # a policy adapt made: its task a novel object's
    adapted.add_copy(PolicyStore(REPO / "assets" / "priors"), "prior", "run.adapt-mug")
    kept = adapted.update("run.adapt-mug", task="mug@A0").experience_file
    for args, message in ((("nope", "--store", str(tmp_path)), "no policy 'nope'"),
                          (("prior", "--out", str(tmp_path), "--transitions", "0"), "--transitions: 0 is below 1"),
                          (("run.adapt-mug", "--store", str(tmp_path / "adapted")), "give its objects directory")):
        result = run_cli("collect-experience", *args)
        assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "prior").exists() and adapted.record("run.adapt-mug").experience_file == kept


def test_train_prior_refuses_a_minimum_above_its_budget_before_training():
    result = run_cli("train-prior", "--min-steps", "5000", "--steps", "3000")
    assert result.returncode == 2 and "--min-steps 5000 must lie between 0 and --steps 3000" in result.stderr
    assert "Traceback" not in result.stderr


def test_train_prior_refuses_an_objects_dir_without_a0_before_training(tmp_path):
    result = run_cli("train-prior", "--objects-dir", str(tmp_path), "--out", str(tmp_path / "priors"))
    assert result.returncode == 2 and f"{tmp_path} holds no A0/model.urdf" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "priors").exists()


PICKLED_PRIOR = REPO / "test" / "data" / "pickled-priors" / "priors" / "prior"


def test_policy_import_refuses_without_trust_and_reads_nothing(tmp_path):
    zip_file = tmp_path / "model.zip"
    shutil.copy(PICKLED_PRIOR / "model-1.zip", zip_file)
    result = run_cli("policy", "import", str(zip_file), "--name", "p", "--store", str(tmp_path / "store"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "unpickles it, which runs any code it holds: pass --trust" in result.stderr
    assert not (tmp_path / "store").exists()


def test_policy_import_converts_a_stores_zip_in_place_keeping_its_record_and_experience(tmp_path):
    """The shipped prior as it was (test/data/pickled-priors, with its experience): the command writes what the
    shipped, converted prior holds, and says that it ran the zip's code."""
    from learner_node.model_files import read_model_file
    from learner_node.policy_store import PolicyStore

    shipped = PolicyStore(REPO / "assets" / "priors")
    folder = tmp_path / "store" / "prior"
    shutil.copytree(PICKLED_PRIOR, folder)
    record = json.loads((folder / "policy.json").read_text())
    shutil.copy(shipped.root / "prior" / shipped.record("prior").experience_file, folder / "experience-1.npz")
    (folder / "policy.json").write_text(json.dumps({**record, "experience_file": "experience-1.npz"}))

    result = run_cli("policy", "import", str(folder / "model-1.zip"), "--trust", "--store", str(tmp_path / "store"))
    assert result.returncode == 0, result.stderr
    assert f"{folder / 'model-1.zip'}: loading it runs the code it holds (--trust)" in result.stdout
    assert sorted(path.name for path in folder.iterdir()) == ["experience-2.npz", "model-2.npz", "policy.json"]
    converted = PolicyStore(tmp_path / "store").record("prior")
    for name in ("task", "steps_trained", "last_score", "last_score_task", "profile", "observation_layout", "extra"):
        assert getattr(converted, name) == record[name], name
    arrays, metadata = read_model_file(folder / converted.model_file)
    shipped_arrays, shipped_metadata = read_model_file(shipped.model_path("prior"))
    assert metadata == shipped_metadata and arrays.keys() == shipped_arrays.keys()
    for name, values in arrays.items():
        np.testing.assert_array_equal(values, shipped_arrays[name], err_msg=name)
        assert values.dtype == shipped_arrays[name].dtype, name
    for name, values in PolicyStore(tmp_path / "store").experience("prior").items():
        np.testing.assert_array_equal(values, shipped.experience("prior")[name], err_msg=name)


def test_policy_import_of_a_bare_zip_takes_a_name_and_a_profile_and_never_overwrites(tmp_path):
    from learner_node.policy_store import PolicyStore

    zip_file = tmp_path / "checkpoint.zip"
    shutil.copy(PICKLED_PRIOR / "model-1.zip", zip_file)
    store = str(tmp_path / "store")
    result = run_cli("policy", "import", str(zip_file), "--trust", "--store", store)
    assert result.returncode == 2 and "no policy.json beside" in result.stderr and "--name" in result.stderr
    result = run_cli("policy", "import", str(zip_file), "--trust", "--store", store, "--name", "p",
                     "--profile", "paper")
    assert result.returncode == 0, result.stderr
    record = PolicyStore(tmp_path / "store").record("p")
    assert (record.profile, record.model_file, record.experience_file) == ("paper", "model-1.npz", "")
    result = run_cli("policy", "import", str(zip_file), "--trust", "--store", store, "--name", "p")
    assert result.returncode == 2 and "policy 'p' exists in" in result.stderr
    assert PolicyStore(tmp_path / "store").record("p").model_file == "model-1.npz" and zip_file.is_file()


def test_launch_refuses_a_bad_or_taken_foxglove_port_before_anything_starts(tmp_path):
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = str(taken.getsockname()[1])
        for args, error in (((port,), "is in use"), (("0",), "expected 1..65535"),
                            (("--foxglove-host", "0.0.0.0"), "needs --foxglove")):
            flags = ("--foxglove", *args) if args[0] != "--foxglove-host" else args
            result = run_cli("launch", "--preset", "smoke", "--out", str(tmp_path / "run"), *flags)
            assert result.returncode == 2 and error in result.stderr, result.stderr
            assert "Traceback" not in result.stderr and not (tmp_path / "run").exists()


def test_launch_refuses_a_tensorboard_directory_it_cannot_write_before_anything_starts(tmp_path):
    (tmp_path / "a-file").write_text("")
    result = run_cli("launch", "--preset", "smoke", "--out", str(tmp_path / "run"),
                     "--tensorboard", str(tmp_path / "a-file" / "curves"))
    assert result.returncode == 2, result.stderr
    assert "--tensorboard" in result.stderr and "not a directory this user can write to" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "run").exists()


def test_launch_and_experiment_refuse_bad_pairs_before_anything_starts(tmp_path):
    import os

    too_many = str((os.cpu_count() or 1) + 1)
    for command, args, error in (
        ("launch", ("--pairs", "0"), "at least one sim/learner pair"),
        ("launch", ("--pairs", too_many), "--force starts them anyway"),
        ("launch", ("--pairs", "2", "--strategy", "random"), "sequential"),
        ("launch", ("--pairs", "2", "--use-sim-time"), "clock of its own"),
        ("launch", ("--pairs", "2", "--remote-pairs", "3"), "expected 0, or 1 to 2"),
        ("experiment", ("--pairs", "2", "--strategies", "glocal,glocal_no_global"), "sequential"),
    ):
        result = run_cli(command, "--preset", "smoke", "--out", str(tmp_path / "run"), *args)
        assert result.returncode == 2 and error in result.stderr, (command, args, result.stderr)
        assert "Traceback" not in result.stderr and not (tmp_path / "run").exists()


def test_pair_refuses_a_directory_without_a_run_of_that_pair_before_anything_starts(tmp_path):
    result = run_cli("pair", "--out", str(tmp_path / "run"), "--index", "1")
    assert result.returncode == 2 and "holds no run" in result.stderr, result.stderr
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.json").write_text('{"strategy": "glocal", "preset": "smoke", "seed": 0, "pairs": 2}')
    result = run_cli("pair", "--out", str(tmp_path / "run"), "--index", "2")
    assert result.returncode == 2 and "is not one of its pairs (0 to 1)" in result.stderr, result.stderr
    assert sorted(path.name for path in (tmp_path / "run").iterdir()) == ["run.json"], "nothing started"
