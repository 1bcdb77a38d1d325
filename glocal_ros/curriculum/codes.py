"""The curriculum's codes as it publishes them: strategy names, statuses, roles.

One definition each, for the strategies, the curriculum node, the CLI and the
analysis of recorded runs. The values are glocal_interfaces'
CurriculumState.STATUS_* and TaskAssignment.ROLE_*; the strategy names are
those CurriculumState.strategy lists (test_rooms checks all of them against
msg_schemas/).
"""

#: The strategies by the names parameters and the CLI use, in the paper's order
#: (tables and legends list them so; ``strategies.STRATEGIES`` runs them).
STRATEGY_NAMES: tuple[str, ...] = (
    "glocal", "random", "alp_gmm_250", "alp_gmm_10", "glocal_no_global", "glocal_random_cluster",
)

# CurriculumState.STATUS_*: what the curriculum is doing.
STATUS_STARTING = 0
STATUS_EVALUATING = 1
STATUS_TRAINING_GLOBAL = 2
STATUS_TRAINING_LOCAL = 3
STATUS_TRAINING = 4  # baselines: one policy over sampled tasks
STATUS_FINISHED = 5

# TaskAssignment.ROLE_*: what a training assignment is for.
ROLE_GLOBAL = 0
ROLE_LOCAL = 1
ROLE_SAMPLED = 2  # baselines: episodes of tasks drawn by a sampler
ROLE_CLUSTER = 3  # glocal_no_global: a task of the cluster's sweep

#: ``RunConfig.baseline_tasks``: what the baselines' samplers draw from (``baselines`` argues the default).
BASELINE_TASKS: tuple[str, ...] = ("all", "unlearned")
