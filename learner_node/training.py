"""One Train goal: SAC from a stored policy on a task, until learned or out of budget.

ROS-free: the envs are anything with the batch interface (the sim node's
client, or ``BatchedEnvs`` in-process for the bench and tests), and the goal's
owner passes in what it needs to hear (progress), to say (stop) and to run
between steps (evaluations others asked for).

The loop is SAC's, written out in ``_Goal.collect`` on a ``BatchVecEnv``
(``_Goal`` writes down the order of one step): stable-baselines3's
``learn`` for SBX's SAC, less its host-side replay buffer and callbacks, with
the buffer and the gradient steps in compiled code (``learner_node.updates``
says what that replaces and what it changes); around it:
- evaluation of ``task`` every ``eval_interval`` env steps and at the end,
  the paper's score (successes out of ``eval_episodes``, deterministic);
  learned means score > threshold (the paper's "above B"); a goal that
  stops when learned checks before its first step too, as "train until
  S > B" does, and stores the initial policy unchanged when it passes;
- a checkpoint (model, replay buffer, progress, the random generators'
  states; arrays and JSON, nothing pickled) every ``checkpoint_interval``
  steps, so that the same goal sent again after a crash continues from it;
  at a checkpoint every running episode is cut and new ones start, from a
  seed derived from the step for a seeded goal, so that a resumed goal goes
  on exactly as the uninterrupted one (the sim's episodes in flight cannot
  be saved);
- the trained model is written to the policy store only when the goal ends
  by itself (budget spent, learned or its episodes done), never half-way; the goal's outcome is
  kept, so the same goal sent again (its client restarted and lost the
  result) gets it back instead of training again.

Choices:
- A goal starts from the stored model with an empty replay buffer (what
  loading an SB3 model gives) or, when the trainer's ``FineTuning`` says so,
  with the experience its initial policy keeps; updates start once a batch
  of transitions is in it; what it acts with until then, its batch, its
  learning rate and how many of its first steps update the critics only are
  the ``FineTuning`` too (``learner_node.sac_settings``).
  ``keep_replay_buffer`` continues the previous goal's model and buffer
  instead, when the goal starts from that goal's output: the baselines
  train one policy through many short goals.
- Only training env steps count against the budget; evaluation steps do not
  (the paper counts training timesteps).
- The N envs step together, so a goal trains whole vector steps and
  never passes its budget: it may stop up to N - 1 steps short of it
  (``steps_used`` says what it trained; the curriculum charges that).
- ``episode_limit`` ends a goal at the vector step where that many training
  episodes have finished (more, when several envs finish at that step); the
  episodes still running are cut, as at any goal's end.
- The gradient steps of a vector step run while the sim computes the next
  one (``learner_node.updates``): SB3's updates, a step later.
- A checkpoint's files are this loop's (``CHECKPOINT_FORMAT``): one of the
  SB3 loop before it is refused, naming what differs, and never resumed.
- With a ``tensorboard_dir``, every progress report and evaluation of a goal
  is also written to its TensorBoard and CSV curves (``learner_node.scalars``).
- Every evaluation of a goal also measures its instruments on probe states
  (``learner_node.instruments``: the critics' value of the parent's and the
  current actions, their distance, the policy's entropy); progress reports
  carry the latest.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from glocal_ros.curriculum.learner import EpisodeSummary, TrainGoal, passes_threshold
from glocal_ros.files import atomic_write
from glocal_ros.seeds import MAX_SEED, derived_seed
from glocal_ros.sim_contract import BatchStepper
from glocal_ros.tasks import check_tasks
from learner_node.evaluation import BatchPolicy, Score, evaluate
from learner_node.fine_tuning import goal_start_actor, start_fine_tuning
from learner_node.instruments import GoalInstruments, Instruments
from learner_node.model_files import load_model, write_model
from learner_node.policies import RANDOM_POLICY, PolicyRegistry, deterministic_actions
from learner_node.policy_store import PolicyRecord, check_name
from learner_node.replay_buffer import Experience
from learner_node.profiles import DEFAULT_PROFILE, PROFILES, LearnerProfile
from learner_node.sac_settings import FineTuning, seed_keys
from learner_node.scalars import RECENT_EPISODES, GoalScalars
from learner_node.updates import Anchor, OverlappedUpdates, TransitionRing, sample_actions
from learner_node.vec_env import BatchVecEnv, TaskCycle

#: Largest step budget of one goal: the paper's whole run is 4M steps; a budget beyond this is a typo
#: (or 2^64 - 1), and would train until cancelled.
DEFAULT_MAX_STEP_BUDGET = 100_000_000
CHECKPOINT_FILE = "checkpoint.json"
#: What a checkpoint of this loop says it is: its buffer is a ``TransitionRing``'s file. The SB3 loop before
#: wrote none (its buffer in rows of N envs, its minibatches from numpy's generator).
CHECKPOINT_FORMAT = "compiled-loop-1"
#: The files a checkpoint names, in its own folder; a ``.zip`` model is of the pickled format before, which
#: ``load_model`` refuses saying so.
_CHECKPOINT_FILES = {"model": re.compile(r"^model-[1-9][0-9]{0,17}\.(npz|zip)$"),
                     "buffer": re.compile(r"^buffer-[1-9][0-9]{0,17}\.npz$")}
#: Keys of a seeded goal's streams (``glocal_ros.seeds.derived_seed``): training, and each evaluation.
TRAINING_STREAM, EVALUATION_STREAM = 0, 1
FINISHED_FILE = "finished.json"
#: The folder of a learner's policy store that holds each Train goal's checkpoint, by output policy.
CHECKPOINTS_DIR = ".checkpoints"


def check_goal(goal: TrainGoal, max_eval_episodes: int = 1_000_000,
               max_step_budget: int = DEFAULT_MAX_STEP_BUDGET) -> None:
    """Raise ``ValueError`` with a message a user can act on, unless this learner can run ``goal``."""
    if not goal.task and not goal.episode_tasks:
        raise ValueError("a goal needs a task or episode_tasks")
    check_tasks([goal.task] if goal.task else [])
    check_tasks(goal.episode_tasks)
    check_name(goal.initial_policy)
    check_name(goal.output_policy)
    if goal.initial_policy == RANDOM_POLICY:
        raise ValueError(f"{RANDOM_POLICY!r} has no model to train from: start from a stored policy")
    if goal.output_policy == RANDOM_POLICY:
        raise ValueError(f"{RANDOM_POLICY!r} is built in and cannot be written")
    if not 1 <= goal.step_budget <= max_step_budget:
        raise ValueError(f"step_budget {goal.step_budget} outside 1..{max_step_budget}")
    if not 0 <= goal.threshold < goal.eval_episodes:
        raise ValueError(f"threshold {goal.threshold} must lie in [0, eval_episodes={goal.eval_episodes})")
    if not 1 <= goal.eval_episodes <= max_eval_episodes:
        raise ValueError(f"eval_episodes {goal.eval_episodes} outside 1..{max_eval_episodes}")
    if goal.episode_limit < 0:
        raise ValueError(f"episode_limit must not be negative, got {goal.episode_limit}")
    if goal.eval_interval < 0:
        raise ValueError(f"eval_interval must not be negative, got {goal.eval_interval}")
    if goal.seed is not None and not 0 <= goal.seed <= MAX_SEED:
        raise ValueError(f"seed {goal.seed} outside 0..{MAX_SEED} (-1 for none)")


class GoalFailed(RuntimeError):
    """Training stopped on an error (the sim went away): what it trained is in the checkpoint."""

    def __init__(self, error: Exception, steps_used: int, checkpoint_step: int):
        super().__init__(f"{type(error).__name__}: {error} (after {steps_used} steps; "
                         f"checkpoint at step {checkpoint_step}, which the same goal resumes)")
        self.steps_used = steps_used
        self.checkpoint_step = checkpoint_step


@dataclass
class TrainProgress:
    steps: int  # training env steps of this goal
    step_budget: int
    episodes: int
    recent_success_rate: float
    latest_score: float  # -1 before the first evaluation
    steps_per_second: float
    mean_episode_return: float = math.nan  # of the same episodes as recent_success_rate
    actor_loss: float = math.nan  # the last gradient step's (NaN before the first)
    critic_loss: float = math.nan
    entropy_coefficient: float = math.nan
    instruments: Instruments = Instruments()  # of the goal's last evaluation (``learner_node.instruments``)

    def scalars(self) -> dict[str, float]:
        """The report as ``learner_node.scalars`` tags it."""
        return {"rollout/success_rate": self.recent_success_rate, "rollout/ep_rew_mean": self.mean_episode_return,
                "train/actor_loss": self.actor_loss, "train/critic_loss": self.critic_loss,
                "train/ent_coef": self.entropy_coefficient, "time/fps": self.steps_per_second}


@dataclass
class TrainOutcome:
    learned: bool
    score: Score | None  # the last evaluation of the task; None when the goal has no task or none ran
    steps_used: int
    episodes: list[EpisodeSummary]
    message: str
    completed: bool  # False: stopped (cancel, shutdown) before its end; nothing was stored


@dataclass
class _GoalState:
    """What a checkpoint keeps besides the model and buffer."""

    steps_used: int = 0
    episodes: list[dict] = field(default_factory=list)
    score: dict | None = None
    learned: bool = False
    steps_at_last_eval: int = 0
    critic_warmup: int = 0  # the goal's first steps whose gradient steps leave the actor as it is
    warm_start_steps: int = 0  # the goal's first steps that run no gradient step (``FineTuning.warm_start_steps``)
    anchored: bool = False  # the actor's loss has ``FineTuning.parent_anchor``'s term


class Trainer:
    """Runs Train goals on ``envs`` with the policies of ``policies``, as ``profile`` learns.

    ``fine_tuning``: how a goal starts from a stored policy, the profile's own unless given (``bench
    transfer`` compares recipes: ``LearnerProfile.with_recipe`` says which a profile allows).
    ``tensorboard_dir``: where each goal writes its training curves (``learner_node.scalars``); None: nowhere.
    """

    def __init__(self, envs: BatchStepper, policies: PolicyRegistry, checkpoint_root: Path, seed: int = 0,
                 checkpoint_interval: int = 5_000, progress_interval_sec: float = 1.0,
                 profile: LearnerProfile = PROFILES[DEFAULT_PROFILE], fine_tuning: FineTuning | None = None,
                 tensorboard_dir: Path | None = None):
        self.envs = envs
        self.tensorboard_dir = None if tensorboard_dir is None else Path(tensorboard_dir)
        self.profile = profile
        self.fine_tuning = fine_tuning or profile.fine_tuning
        self.policies = policies
        self.checkpoint_root = Path(checkpoint_root)
        self.seed = seed
        self.checkpoint_interval = checkpoint_interval
        self.progress_interval_sec = progress_interval_sec
        self.total_steps = 0  # training env steps over all goals, for the episode records
        self._warm: tuple[str, str, object, TransitionRing] | None = None  # (policy, model file, model, buffer)

    @property
    def learner_key(self) -> dict:
        """What besides the spec decides a goal: a checkpoint of another profile or recipe is not resumed."""
        return {"profile": self.profile.name, "fine_tuning": self.fine_tuning.key()}

    def train(
        self,
        spec: TrainGoal,
        on_progress: Callable[[TrainProgress], None] = lambda progress: None,
        should_stop: Callable[[], str] = lambda: "",
        between_steps: Callable[[], bool] = lambda: False,
        on_evaluation: Callable[[Score, int], None] = lambda score, steps: None,
    ) -> TrainOutcome:
        """Run ``spec`` to its end; ``should_stop`` returns a reason to stop early ("" to go on).

        ``on_evaluation`` hears every evaluation of ``spec.task`` the goal runs (the check before
        the first step, each interval, the end) as soon as it is scored, with the goal's training
        steps it scored the policy after: the record of what the goal's decisions were based on.
        """
        self.check_initial_policy(spec.initial_policy)
        finished = self._finished_before(spec, self.checkpoint_root / spec.output_policy)
        if finished is not None:
            return finished
        return _Goal(self, spec, on_progress, should_stop, between_steps, on_evaluation).run()

    def check_initial_policy(self, name: str) -> None:
        """``ValueError`` unless a goal of this trainer may start from ``name``: a policy of its profile
        that acts on the sim's observation layout."""
        record = self.policies.record(name)
        record.check_observation_layout()
        if not self.profile.trains_policies_of(record.profile):
            raise ValueError(f"policy {name!r} was trained under learner profile {record.profile!r}, and this "
                             f"learner runs profile {self.profile.name!r}: start from a policy of "
                             f"{self.profile.name!r} (its shipped prior is in assets/{self.profile.prior_store})")

    def evaluation_policy(self, name: str, tasks: Sequence[str], seed: int | None = None) -> BatchPolicy:
        """``name`` acting as a goal of this trainer on any of ``tasks`` starts it, before its first step.

        So ``learner/evaluate`` and a goal's check before its first step score one network: with
        ``new_task_inputs="trained-mean"`` the goal edits the task inputs before that check.
        """
        if name == RANDOM_POLICY or self.fine_tuning.new_task_inputs == "initial":
            return self.policies.load(name, seed)
        return deterministic_actions(goal_start_actor(self.policies.model(name), self.fine_tuning, tasks))

    def _mark_finished(self, folder: Path, spec: TrainGoal, state: _GoalState, model_file: str) -> None:
        """Replace the checkpoint by the goal's outcome: a client that lost the result may ask again."""
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        text = json.dumps({"spec": _spec_key(spec), "learner": self.learner_key, "state": asdict(state),
                           "model_file": model_file}).encode()
        atomic_write(folder / FINISHED_FILE, lambda stream: stream.write(text))

    def _finished_before(self, spec: TrainGoal, folder: Path) -> TrainOutcome | None:
        """The outcome of this very goal when it finished before and its policy is unchanged since."""
        finished = _read_json(folder / FINISHED_FILE, ("spec", "state", "model_file"))
        if finished is None:
            return None
        if finished["spec"] != _spec_key(spec) or spec.output_policy not in self.policies.store:
            return None
        if finished.get("learner") != self.learner_key:
            return None
        if self.policies.store.record(spec.output_policy).model_file != finished["model_file"]:
            return None
        state = _GoalState(**finished["state"])
        return _outcome(state, True, f"finished before, not trained again: {state.steps_used} steps")

    def _store(self, spec: TrainGoal, model, ring: TransitionRing, state: _GoalState) -> PolicyRecord:
        parent = self.policies.record(spec.initial_policy)
        record = PolicyRecord(
            name=spec.output_policy, task=spec.task or ",".join(sorted(set(spec.episode_tasks))),
            parent=spec.initial_policy, steps_trained=parent.steps_trained + state.steps_used,
            last_score=float(state.score["successes"]) if state.score else -1.0,
            last_score_task=spec.task if state.score else "", profile=self.profile.name,
            extra={"learned": state.learned, "threshold": spec.threshold, "eval_episodes": spec.eval_episodes},
        )
        experience = self.fine_tuning.experience
        stored = self.policies.store.save(model, record, ring.recent(experience) if experience else None)
        self._warm = (spec.output_policy, str(self.policies.store.root / stored.name / stored.model_file), model,
                      ring)
        return stored

    def _warm_model(self, spec: TrainGoal) -> tuple[object, TransitionRing] | None:
        """The previous goal's model and buffer when ``spec`` continues it (``keep_replay_buffer``), else None."""
        store_path = str(self.policies.model_path(spec.initial_policy))
        if spec.keep_replay_buffer and self._warm and self._warm[:2] == (spec.initial_policy, store_path):
            return self._warm[2], self._warm[3]
        return None


class _Goal:
    """One Train goal from its first step to its outcome: the state it owns and the order of a step.

    The loop is ``collect``; each vector step runs, in this order (SB3's):
    1. ``at_step_start``: when a checkpoint is due, the owed gradient steps
       are paid, the checkpoint written, and the running episodes cut
       (``cut_episodes``).
    2. ``actions``: the N actions, uniform at random before
       ``learning_starts``, else sampled from the policy.
    3. ``BatchVecEnv.step_wait`` sends them; while the sim computes the step,
       the previous step's transitions and gradient steps are paid in one
       compiled call (``OverlappedUpdates``); with the step back,
       ``between_steps`` runs the owner's jobs and, when due, the interval
       evaluation.
    4. ``after_step`` (before the transitions are stored): counts, finished
       episodes, progress, the stop check, and this step's gradient steps
       owed. A step that ends the goal is not stored, as in SB3.
    5. The step's transitions wait for the next payment.
    At the end: the last evaluation (unless one ran at that very step), the
    policy stored, the outcome kept for a client that asks again.
    """

    def __init__(self, trainer: Trainer, spec: TrainGoal, on_progress: Callable[[TrainProgress], None],
                 should_stop: Callable[[], str], between_steps: Callable[[], bool],
                 on_evaluation: Callable[[Score, int], None]):
        self.trainer, self.spec, self.tuning = trainer, spec, trainer.fine_tuning
        self.on_progress, self.should_stop, self.owner_between_steps = on_progress, should_stop, between_steps
        self.on_evaluation = on_evaluation
        self.checkpoint_dir = trainer.checkpoint_root / spec.output_policy
        self.state = _GoalState()
        self.cycle = TaskCycle(spec.episode_tasks or (spec.task,))
        initial = trainer.policies.model(spec.initial_policy)  # SB3 refuses an env whose Box bounds differ
        self.vec_env = BatchVecEnv(trainer.envs, initial.observation_space, initial.action_space, self.cycle,
                                   policy_name=spec.output_policy, global_step=lambda: trainer.total_steps,
                                   between_steps=self.between_steps,
                                   time_limit_terminal=trainer.profile.time_limit_terminal)
        self.model, self.ring, self.resumed = self.model_to_train()
        self.instruments = GoalInstruments(initial, self.parent_experience)
        self.latest_instruments = Instruments()
        self.seed_streams()
        self.tune()
        self.start_timesteps = self.model.num_timesteps - self.state.steps_used  # the model's count at step 0
        self.updates = OverlappedUpdates(self.model, self.ring, inclusive_start=self.tuning.random_steps is not None,
                                         anchor=self.anchor(initial))
        self.vec_env.while_stepping = self.updates.pay
        self.last_checkpoint = self.state.steps_used
        self.last_progress = 0.0
        self.started = time.monotonic()
        self.recent: deque[bool] = deque(maxlen=RECENT_EPISODES)  # successes of the last episodes, for progress
        self.recent_returns: deque[float] = deque(maxlen=RECENT_EPISODES)
        self.scalars: GoalScalars | None = None
        self.stop_reason = ""
        self.observations: np.ndarray | None = None  # the envs' latest, which the next actions act on

    def model_to_train(self) -> tuple[object, TransitionRing, int]:
        """The model to train, its replay buffer and the step it resumes from (0 for a new goal)."""
        spec, trainer = self.spec, self.trainer
        saved = _read_checkpoint(self.checkpoint_dir)
        if saved is not None and saved["spec"] == _spec_key(spec):
            if saved.get("format") != CHECKPOINT_FORMAT:
                raise ValueError(f"the checkpoint of {spec.output_policy!r} at step {saved['state']['steps_used']} "
                                 f"is of format {saved.get('format', 'sb3-loop (none named)')!r}, and this learner "
                                 f"resumes {CHECKPOINT_FORMAT!r} (its replay buffer and minibatches are another "
                                 f"loop's): delete {self.checkpoint_dir} to train the goal again")
            if saved.get("learner") != trainer.learner_key:
                raise ValueError(f"the checkpoint of {spec.output_policy!r} at step {saved['state']['steps_used']} "
                                 f"was trained with {saved.get('learner')}, this learner runs "
                                 f"{trainer.learner_key}: send the goal to a learner of those settings, or "
                                 f"delete {self.checkpoint_dir} to train it again")
            model = load_model(self.checkpoint_dir / saved["model"], env=self.vec_env)
            ring = TransitionRing.for_model(model)
            if not ring.load(self.checkpoint_dir / saved["buffer"]):
                self.start_buffer(model, ring)
            try:
                self.state = _GoalState(**saved["state"])
                restore_random_state(model, saved["random_state"])
                self.cycle.position = int(saved["task_position"])
            except (KeyError, TypeError, ValueError) as error:
                raise ValueError(f"{self.checkpoint_dir / CHECKPOINT_FILE}: not a checkpoint's state "
                                 f"({type(error).__name__}: {error})") from error
            return model, ring, self.state.steps_used
        warm = trainer._warm_model(spec)
        if warm is not None:
            model, ring = warm
            model.set_env(self.vec_env, force_reset=True)
            if self.tuning.rearm_warm:
                model.learning_starts = model.num_timesteps + self.tuning.random_steps
            return model, ring, 0
        model = load_model(str(trainer.policies.model_path(spec.initial_policy)), env=self.vec_env)
        ring = TransitionRing.for_model(model)
        self.start_buffer(model, ring)
        # A warm model's critic has seen its data, and its actor is the goal's start.
        self.state.critic_warmup = self.tuning.critic_warmup
        self.state.warm_start_steps = self.tuning.warm_start_steps
        self.state.anchored = self.tuning.parent_anchor > 0
        start_fine_tuning(model, self.tuning, spec.episode_tasks or (spec.task,))
        return model, ring, 0

    def anchor(self, initial) -> Anchor | None:
        """``FineTuning.parent_anchor``'s anchor: the actor the goal started with, from the stored ``initial``
        model (so a resumed goal anchors where the goal began)."""
        if not self.state.anchored:
            return None
        start = goal_start_actor(initial, self.tuning, self.spec.episode_tasks or (self.spec.task,))
        return Anchor(start.actor_state.params, self.tuning.parent_anchor, self.tuning.anchor_decay_steps,
                      self.start_timesteps)

    @cached_property
    def parent_experience(self) -> Experience | None:
        """The transitions the initial policy keeps, read once: the buffer's start and the instruments' probes."""
        return self.trainer.policies.experience(self.spec.initial_policy)

    def start_buffer(self, model, ring: TransitionRing) -> None:
        """Fill the new model's empty buffer with the initial policy's experience (``FineTuning.experience``),
        and act as ``FineTuning.first_actions`` says until its random steps are over (``OverlappedUpdates``
        waits for a batch in the buffer)."""
        if self.tuning.experience:
            experience = self.parent_experience
            if experience is not None:
                ring.add({name: values[-self.tuning.experience:] for name, values in experience.items()})
        random_steps = 0
        if self.tuning.first_actions == "random":
            random_steps = self.tuning.random_steps or self.tuning.batch_size or model.batch_size
        model.learning_starts = model.num_timesteps + random_steps

    def tune(self) -> None:
        """The goal's schedule on whichever model it trains (stored, checkpointed or warm): its batch, and the
        learning rates its optimisers step with (what SBX's ``train`` sets before each update)."""
        model = self.model
        if self.tuning.batch_size is not None:
            model.batch_size = self.tuning.batch_size
        if self.tuning.learning_rate is not None:
            model.learning_rate = self.tuning.learning_rate
            model._setup_lr_schedule()
        rate = model.lr_schedule(model._current_progress_remaining)
        model.policy.actor_state.opt_state.hyperparams["learning_rate"] = self.tuning.actor_learning_rate or rate
        model.policy.qf_state.opt_state.hyperparams["learning_rate"] = model.initial_qf_learning_rate or rate

    def seed_streams(self) -> None:
        """Seed the goal's random streams: SAC's sampling and, for a seeded goal, its sim episodes.

        A goal with a seed is a function of its initial policy, its spec and
        its seed, whatever ran on the learner and the sim before it: every
        stream it draws from starts from a seed derived from it (numpy and
        the action space through SB3's ``set_random_seed``, SBX's JAX keys, env k's
        episodes from that seed + k at the first reset; each evaluation's
        episodes from a seed of their own, see ``evaluate``). A goal
        resumed from its checkpoint at step s goes on exactly as the goal that
        was not interrupted: the checkpoint holds the generators' states, and
        both start new episodes there from a seed derived from s (see
        ``cut_episodes``). The exception: a warm model (``keep_replay_buffer``)
        brings the previous goal's buffer, which a restarted learner no longer
        has. Without a seed, a new model is seeded with the trainer's seed and
        the sim's episodes continue its own streams; a warm model continues its
        streams.
        """
        from stable_baselines3.common.utils import set_random_seed

        spec, model, trainer = self.spec, self.model, self.trainer
        if self.resumed:  # the generators are the checkpoint's; the episodes start as the cut's did
            if spec.seed is not None:
                self.vec_env.seed(derived_seed(spec.seed, TRAINING_STREAM, self.resumed))
        elif spec.seed is not None:
            seed = derived_seed(spec.seed, TRAINING_STREAM, 0)
            model.set_random_seed(seed)  # the vec env's first reset too
            seed_keys(model, seed)
        elif not (trainer._warm and trainer._warm[2] is model):
            set_random_seed(trainer.seed)  # what model.set_random_seed does, less the envs' seeds
            model.action_space.seed(trainer.seed)
            seed_keys(model, trainer.seed)

    @property
    def steps(self) -> int:
        """The goal's training env steps so far (a vector step counts once it is back)."""
        return self.model.num_timesteps - self.start_timesteps

    def collect(self, env_steps: int) -> None:
        """SAC on the envs for ``env_steps`` env steps (whole vector steps) or until ``after_step`` ends it."""
        model, vec_env = self.model, self.vec_env
        end = model.num_timesteps + env_steps
        self.observations = vec_env.reset()
        while model.num_timesteps < end:
            self.at_step_start()
            observations = self.observations
            actions, stored_actions = self.actions(observations)
            vec_env.step_async(actions)
            next_observations, rewards, dones, infos = vec_env.step_wait()
            model.num_timesteps += vec_env.num_envs
            if not self.after_step():
                return
            self.updates.store(transitions(observations, next_observations, stored_actions, rewards, dones, infos))
            self.observations = next_observations

    def actions(self, observations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The envs' actions and those the buffer stores, as SB3's ``_sample_action`` makes them: uniform
        random before ``learning_starts``, else sampled from the policy (``predict``'s numbers, one call)."""
        model = self.model
        policy = model.policy
        if model.num_timesteps < model.learning_starts:
            unscaled = np.array([model.action_space.sample() for _ in range(self.vec_env.num_envs)])
        else:
            sampled = sample_actions(policy, observations)
            unscaled = policy.unscale_action(np.clip(sampled.reshape((-1, *model.action_space.shape)), -1, 1))
        stored = policy.scale_action(unscaled)
        return policy.unscale_action(stored), stored

    def run(self) -> TrainOutcome:
        if self.trainer.tensorboard_dir is not None:
            self.scalars = GoalScalars(self.trainer.tensorboard_dir / self.spec.output_policy)
        try:
            return self.train()
        finally:
            if self.scalars is not None:
                self.scalars.close()

    def train(self) -> TrainOutcome:
        """The goal's first check, its steps, then its outcome."""
        spec, state, trainer = self.spec, self.state, self.trainer
        if spec.stop_when_learned and spec.task and state.score is None:
            # "Train until S > B" checks first: a policy that passes already is not trained.
            self.evaluate(state.steps_used)
        remaining = spec.step_budget - state.steps_used
        # The N envs step together: whole steps of N only, so the goal never passes its budget.
        remaining -= remaining % self.vec_env.num_envs
        if remaining > 0 and not (spec.stop_when_learned and state.learned):
            try:
                with self.updates:
                    self.collect(remaining)
            except BaseException as error:
                # The sim went away, or the process is stopping: keep what was trained.
                if state.steps_used > self.last_checkpoint:
                    self.save_checkpoint()
                trainer._warm = None
                if isinstance(error, Exception):
                    raise GoalFailed(error, state.steps_used, self.last_checkpoint) from error
                raise
        if self.stop_reason:
            self.save_checkpoint()
            trainer._warm = None
            return _outcome(state, False, f"stopped after {state.steps_used} steps: {self.stop_reason}")
        if spec.task and (state.score is None or state.steps_at_last_eval != state.steps_used):
            self.evaluate(state.steps_used)
        stored = trainer._store(spec, self.model, self.ring, state)
        verdict = ("learned" if state.learned else "not learned") if spec.task else "trained"
        message = f"{verdict} after {state.steps_used} steps"
        if self.resumed:
            message += f" (resumed from a checkpoint at step {self.resumed})"
        trainer._mark_finished(self.checkpoint_dir, spec, state, stored.model_file)
        return _outcome(state, True, message)

    def at_step_start(self) -> None:
        """Step 1: before the actions are drawn, the last step's transitions are stored, so a checkpoint
        here holds everything the next step depends on."""
        if self.steps - self.last_checkpoint >= self.trainer.checkpoint_interval:
            with self.updates.settled():
                self.save_checkpoint()
            self.cut_episodes()

    def between_steps(self) -> bool:
        """Step 3, with the step back: True when the envs were used (their episodes are gone)."""
        used = self.owner_between_steps()
        # This step's count: the loop adds the step to num_timesteps after it returns. Evaluating
        # here, not in ``after_step``, scores the policy at exactly the interval (``after_step``
        # would see the same model: updates through the step before), and a goal that then stops
        # has steps_used equal to the evaluation's step, so the end does not evaluate it again (a
        # second score could undo "learned").
        steps = self.steps + self.vec_env.num_envs
        spec = self.spec
        if spec.task and spec.eval_interval and steps - self.state.steps_at_last_eval >= spec.eval_interval:
            self.updates.pay()
            self.evaluate(steps)
            used = True
        return used

    def after_step(self) -> bool:
        """Step 4: False ends the goal."""
        spec, state, steps = self.spec, self.state, self.steps
        self.trainer.total_steps += self.vec_env.num_envs
        state.steps_used = steps
        while self.vec_env.finished:
            episode = self.vec_env.finished.popleft()
            state.episodes.append(asdict(episode))
            self.recent.append(episode.success)
            self.recent_returns.append(episode.episode_return)
        now = time.monotonic()
        if now - self.last_progress >= self.trainer.progress_interval_sec:
            self.last_progress = now
            self.report_progress(steps, now)
        self.stop_reason = self.should_stop()
        keep_going = (not self.stop_reason and not (spec.stop_when_learned and state.learned)
                      and not (spec.episode_limit and len(state.episodes) >= spec.episode_limit))
        # The step that stops the goal owes no updates (SB3's loop returns before them); nor do warm-start ones.
        if keep_going and steps > state.warm_start_steps:
            self.updates.owe(self.vec_env.num_envs, critic_only=steps <= state.critic_warmup)
        return keep_going

    def report_progress(self, steps: int, now: float) -> None:
        """A progress report to the owner, and to the goal's curves."""
        info = self.updates.last_info()  # waits for the last step's gradient steps
        progress = TrainProgress(
            steps, self.spec.step_budget, len(self.state.episodes),
            float(np.mean(self.recent)) if self.recent else 0.0,
            self.state.score["successes"] if self.state.score else -1.0,
            (steps - self.resumed) / max(now - self.started, 1e-9),
            float(np.mean(self.recent_returns)) if self.recent_returns else math.nan,
            info.actor_loss, info.critic_loss, info.entropy_coefficient, self.latest_instruments)
        self.on_progress(progress)
        if self.scalars is not None:
            self.scalars.write(steps, progress.scalars())

    def cut_episodes(self) -> None:
        """End every running episode and start new ones, as a goal resumed from a checkpoint here starts.

        The cut episodes' last transitions are in the buffer as they were (not
        done: SAC bootstraps from their next observation, as at a time limit);
        the sim records the episodes as interrupted.
        """
        if self.spec.seed is not None:
            self.vec_env.seed(derived_seed(self.spec.seed, TRAINING_STREAM, self.steps))
        self.observations = self.vec_env.reset()

    def evaluate(self, steps: int) -> None:
        """Score the model on the goal's task as the policy after ``steps`` of the goal's training steps."""
        spec, state = self.spec, self.state
        seed = None if spec.seed is None else derived_seed(spec.seed, EVALUATION_STREAM, steps)
        (score,) = evaluate(self.trainer.envs, deterministic_actions(self.model.policy), [spec.task],
                            spec.eval_episodes, policy_name=spec.output_policy, seed=seed,
                            global_step=self.trainer.total_steps)
        state.score = asdict(score)
        state.learned = passes_threshold(score.successes, spec.threshold)
        state.steps_at_last_eval = steps
        self.latest_instruments = self.instruments.measure(self.model, self.ring)
        self.on_evaluation(score, steps)
        if self.scalars is not None:
            self.scalars.write(steps, {"eval/successes": score.successes,
                                       "eval/success_rate": score.successes / score.episodes,
                                       **self.latest_instruments.scalars()})
        self.report_progress(steps, time.monotonic())  # every evaluation's instruments reach the owner

    def save_checkpoint(self) -> None:
        """Model and buffer under new names, then the json naming them: a kill leaves the last whole one."""
        folder, model = self.checkpoint_dir, self.model
        folder.mkdir(parents=True, exist_ok=True)
        previous = _read_checkpoint(folder)
        version = previous["version"] + 1 if previous else 1
        model_file, buffer_file = f"model-{version}.npz", f"buffer-{version}.npz"
        atomic_write(folder / model_file, lambda stream: write_model(model, stream))
        atomic_write(folder / buffer_file, self.ring.save)
        text = json.dumps({"format": CHECKPOINT_FORMAT, "version": version, "spec": _spec_key(self.spec),
                           "learner": self.trainer.learner_key,
                           "model": model_file, "buffer": buffer_file, "state": asdict(self.state),
                           "random_state": random_state(model), "task_position": self.cycle.position}).encode()
        atomic_write(folder / CHECKPOINT_FILE, lambda stream: stream.write(text))
        if previous:
            for name in (previous["model"], previous["buffer"]):
                (folder / name).unlink(missing_ok=True)
        self.last_checkpoint = self.state.steps_used


def _outcome(state: _GoalState, completed: bool, message: str) -> TrainOutcome:
    score = Score(**state.score) if state.score else None
    return TrainOutcome(state.learned, score, state.steps_used,
                        [EpisodeSummary(**e) for e in state.episodes], message, completed)


def transitions(observations: np.ndarray, next_observations: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
                dones: np.ndarray, infos: list[dict]) -> dict[str, np.ndarray]:
    """One vector step's transitions as SB3's ``_store_transition`` and ``ReplayBuffer.add`` keep them: an
    episode that ended has its last observation as the next one, and a time limit is marked as such."""
    next_observations = np.array(next_observations, dtype=np.float32)
    for i in np.flatnonzero(dones):
        if infos[i].get("terminal_observation") is not None:
            next_observations[i] = infos[i]["terminal_observation"]
    return {"observations": np.array(observations, dtype=np.float32), "next_observations": next_observations,
            "actions": np.asarray(actions, dtype=np.float32), "rewards": np.asarray(rewards, dtype=np.float32),
            "dones": np.asarray(dones, dtype=np.float32),
            "timeouts": np.array([info.get("TimeLimit.truncated", False) for info in infos], dtype=np.float32)}


def random_state(model) -> dict:
    """Every generator a SAC goal draws from that its saved model does not keep: SBX's key of the gradient
    steps and their minibatches (its load seeds it again), numpy's global one, the action space's (actions
    before learning starts). The policy's own key is in the model file."""
    keys, position, has_gauss, cached_gaussian = np.random.get_state()[1:]
    return {"jax": np.asarray(model.key).tolist(),
            "numpy": {"keys": keys.tolist(), "position": position, "has_gauss": has_gauss,
                      "cached_gaussian": cached_gaussian},
            "action_space": model.action_space.np_random.bit_generator.state}


def restore_random_state(model, saved: dict) -> None:
    import jax.numpy as jnp

    model.key = jnp.asarray(saved["jax"], dtype=jnp.uint32)
    numpy = saved["numpy"]
    np.random.set_state(("MT19937", np.array(numpy["keys"], dtype=np.uint32), numpy["position"],
                         numpy["has_gauss"], numpy["cached_gaussian"]))
    model.action_space.np_random.bit_generator.state = saved["action_space"]


def _read_checkpoint(folder: Path) -> dict | None:
    """The checkpoint in ``folder`` (None: none); ``ValueError`` naming its file when it is not one, or names a
    file outside the folder or of another kind."""
    path = folder / CHECKPOINT_FILE
    saved = _read_json(path, ("version", "spec", "model", "buffer", "state", "random_state", "task_position"))
    for key, pattern in _CHECKPOINT_FILES.items():
        if saved is not None and not (isinstance(saved[key], str) and pattern.match(saved[key])):
            raise ValueError(f"{path}: {key} {saved[key]!r} is not a file of this checkpoint: refusing to load it")
    return saved


def _read_json(path: Path, keys: Sequence[str]) -> dict | None:
    """The JSON object in ``path`` with at least ``keys`` (None: no file); ``ValueError`` naming ``path`` when it
    is not one (a pickle planted there is not JSON, and is never unpickled)."""
    if not path.is_file():
        return None
    try:
        saved = json.loads(path.read_bytes())
    except ValueError as error:
        raise ValueError(f"{path}: not JSON ({error})") from error
    if not isinstance(saved, dict) or not set(keys) <= set(saved):
        raise ValueError(f"{path}: not an object with {', '.join(keys)}")
    return saved


def _spec_key(spec: TrainGoal) -> dict:
    """The goal as its checkpoint stores it: the same goal sent again resumes it."""
    return json.loads(json.dumps(asdict(spec)))
