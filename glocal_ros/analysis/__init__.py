"""Offline analysis of recorded runs: read bags, draw the paper's figures, write a report.

Everything here reads rosbag2 directories with ``rosbags`` and never talks to
a live graph, so it works without a ROS environment (no rclpy import).

- :mod:`glocal_ros.analysis.runs`: a run directory's bags -> :class:`RunData`,
  plus the statistics across seeds (milestones, Welch's t-test).
- :mod:`glocal_ros.analysis.estimates`: few-seed statistics as rliable computes them (IQM and
  probability of improvement with stratified bootstrap intervals), numpy and scipy only.
- :mod:`glocal_ros.analysis.figures`: matplotlib (Agg) figures as PNG files.
- :mod:`glocal_ros.analysis.report`: ``write_report`` and the ``glocal-ros report`` command.
"""

from glocal_ros.analysis.runs import RunData, find_bags, read_run, read_runs

__all__ = ["RunData", "find_bags", "read_run", "read_runs"]
