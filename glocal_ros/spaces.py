"""Sizes of the paper's observation and action (Section IV-A)."""

from glocal_ros.tasks import NUM_TASKS

#: one-hot task (49) + gripper pose (6) + object pose (6) + two finger-contact bits.
OBS_DIM = NUM_TASKS + 6 + 6 + 2
#: gripper open/close, rotation about the table normal, 3D translation.
ACTION_DIM = 5
