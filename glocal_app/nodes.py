"""The graph's nodes: ``ros2 run glocal_ros NODE`` and ``glocal-ros run NODE`` for each.

Each is a package ``NODE/`` with a module ``NODE/NODE.py`` whose ``main``
runs it, and a wrapper ``bin/NODE`` that setup.py installs into
``lib/glocal_ros``. setup.py reads this file without importing the package
(no dependency is installed when it runs), so it imports nothing.
"""

NODES: tuple[str, ...] = ("sim_node", "learner_node", "curriculum_node", "recorder_node", "foxglove_bridge_node")
