"""glocal_app: the application room, above the nodes.

The ``glocal-ros`` command line (``cli``, ``bag_cli``), ``launch`` and
``experiment`` (``launch``), the one-shot ROS clients behind commands
(``commands``), nodes as child processes (``processes``) and the benchmarks
(``benches``). It is the only room that imports several node packages; the
nodes import nothing from here, and ``glocal_ros`` (the library) nothing
from here or from any node.
"""
