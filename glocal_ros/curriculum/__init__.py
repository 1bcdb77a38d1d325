"""Curriculum strategies without ROS: GloCAL, its ablations and the paper's baselines.

A strategy drives a ``Learner`` (evaluate policies on tasks, train a task
from a policy into a policy with a budget) through a ``Run``, which keeps the
bookkeeping every strategy shares: the step budget, learned tasks,
milestones, and the state a node publishes. ``curriculum_node`` adapts the
``Learner`` protocol onto the learner node's action and service; tests use
an honest test double.

Strategy names, statuses and roles: ``glocal_ros.curriculum.codes``.
"""
