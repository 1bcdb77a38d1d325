"""The learner's gradient steps run while the sim steps: SB3's updates, a step later, none lost."""

from glocal_ros.paths import assets_dir
from learner_node.policies import PolicyRegistry
from learner_node.policy_store import PolicyStore
from learner_node.sac_settings import SAC_KWARGS
from learner_node.training import Trainer, TrainSpec
from sim_node.batch import BatchedEnvs
from sim_node.grasp_env import GraspEnv


class SplitSteps:
    """In-process envs with the sim client's ``start_step``; notes when a step is out."""

    def __init__(self, envs: BatchedEnvs):
        self.envs = envs
        self.step_out = False

    def reset(self, *request):
        return self.envs.reset(*request)

    def step(self, *request):
        return self.envs.step(*request)

    def start_step(self, *request):
        self.step_out = True
        batch = self.envs.step(*request)

        def finish():
            self.step_out = False
            return batch

        return finish


def test_each_steps_updates_run_during_the_next_step_and_the_last_at_the_end(tmp_path, monkeypatch):
    from stable_baselines3 import SAC

    num_envs, batch_size = 2, SAC_KWARGS["batch_size"]
    envs = SplitSteps(BatchedEnvs(lambda i: GraspEnv("A0"), num_envs, "A0"))
    policies = PolicyRegistry(PolicyStore(tmp_path / "store"), [PolicyStore(assets_dir() / "priors")])
    train_calls: list[tuple[bool, int]] = []  # (a step was out, gradient steps)
    real_train = SAC.train

    def noted_train(model, gradient_steps, batch_size=64):
        train_calls.append((envs.step_out, gradient_steps))
        return real_train(model, gradient_steps, batch_size)

    monkeypatch.setattr(SAC, "train", noted_train)
    vector_steps_with_updates = 20
    step_budget = batch_size + num_envs * vector_steps_with_updates
    try:
        outcome = Trainer(envs, policies, tmp_path / "checkpoints").train(TrainSpec(
            "A0", "prior", "a0", step_budget=step_budget, threshold=0, eval_episodes=1))
    finally:
        envs.envs.close()

    assert outcome.completed and outcome.steps_used == step_budget
    # SB3: updates once more than batch_size steps are in, one per env step (gradient_steps=-1).
    assert sum(steps for _, steps in train_calls) == num_envs * vector_steps_with_updates
    assert train_calls == [(True, num_envs)] * (vector_steps_with_updates - 1) + [(False, num_envs)]
    stored = policies.model("a0")
    assert stored.gradient_steps == SAC_KWARGS["gradient_steps"]  # the overlap is not saved with the model
    assert stored._n_updates - policies.model("prior")._n_updates == num_envs * vector_steps_with_updates
