"""``glocal-ros replay`` and ``glocal-ros bag check|repair|render``: the command-line side of recorded bags.

Only argparse lives here: each command imports what it runs when it runs,
so that ``glocal-ros`` stays importable without rclpy (replay needs it, the
bag commands do not).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def cmd_replay(args: argparse.Namespace) -> int:
    from recorder_node.replay import replay

    return replay(args.bag, rate=args.rate, topics=args.topics, loop=args.loop, start_offset=args.start_offset,
                  episode=args.episode, step_period=args.step_period, wait=args.wait)


def cmd_bag_check(args: argparse.Namespace) -> int:
    """Messages per topic and the episode sequence; exit code 1 when episodes are missing or repeated.

    The episodes topic is found under whatever namespace the bag was recorded
    in; a bag of several sim nodes (one namespace each) gets one check per node.
    """
    from glocal_ros.recording import episode_sequence, episode_topics, message_counts
    from glocal_ros.topics import EPISODES_TOPIC

    counts = message_counts(args.bag)
    width = max((len(topic) for topic in counts), default=0)
    for topic, count in counts.items():
        print(f"{topic:<{width}}  {count:>8}")
    ok = True
    for topic in episode_topics(args.bag) or [EPISODES_TOPIC]:
        check = episode_sequence(args.bag, topic)
        print(f"{topic}: {check.summary()}")
        ok = ok and check.ok
    return 0 if ok else 1


def cmd_bag_repair(args: argparse.Namespace) -> int:
    from glocal_ros.bag_repair import repair_bag

    result = repair_bag(args.bag)
    total = sum(result.counts.values())
    if not result.repaired:
        print(f"{result.bag} is intact ({total} messages): nothing to repair, nothing changed")
        return 0
    print(f"recovered {total} messages into {result.bag}; the damaged original is kept as {result.damaged}")
    width = max((len(topic) for topic in result.counts), default=0)
    for topic, count in result.counts.items():
        print(f"{topic:<{width}}  {count:>8}")
    if result.dropped_bytes:
        print(f"dropped the last {result.dropped_bytes} bytes: no complete record (the write the recorder died in)")
    if result.dropped_chunks:
        print(f"dropped {result.dropped_chunks} chunks that did not decompress")
    if result.skipped_messages:
        print(f"skipped {result.skipped_messages} messages of channels without a message definition")
    return 0


def add_bag_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``replay`` and ``bag`` (``check``, ``repair``) to the subcommands of ``glocal-ros``."""
    replay = commands.add_parser("replay", help="republish a recorded bag with its timing, as `ros2 bag play`")
    replay.add_argument("bag", type=Path, help="rosbag2 directory")
    replay.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    replay.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics, as recorded (default: all)")
    replay.add_argument("--loop", action="store_true", help="start over at the end, until Ctrl-C")
    replay.add_argument("--start-offset", type=float, default=0.0, metavar="SECONDS",
                        help="skip this much of the bag (of the episode with --episode)")
    replay.add_argument("--episode", type=int, metavar="SEQ",
                        help="instead: the joint states of the EpisodeRecord with this seq on /joint_states")
    replay.add_argument("--step-period", type=float, metavar="SECONDS",
                        help="with --episode: seconds per env step (default: the env's control period, "
                             "physics substeps x timestep = 10/240 s)")
    replay.add_argument("--wait", type=float, default=5.0, metavar="SECONDS",
                        help="before playing, wait this long at most for every topic to have a subscriber "
                             "(default 5)")
    replay.set_defaults(func=cmd_replay)

    bag = commands.add_parser("bag", help="recorded bags: check (counts, episode gaps), repair (a killed recorder's), "
                                  "render (one frame, from the bag alone)")
    bag_commands = bag.add_subparsers(dest="bag_command", required=True)
    check = bag_commands.add_parser("check", help="messages per topic and gaps in the episode seq (exit 1 on gaps)")
    check.add_argument("bag", type=Path, help="rosbag2 directory")
    check.set_defaults(func=cmd_bag_check)
    repair = bag_commands.add_parser("repair", help="recover a killed recorder's bag; the original is kept as "
                                                    "BAG.damaged")
    repair.add_argument("bag", type=Path, help="rosbag2 directory")
    repair.set_defaults(func=cmd_bag_repair)
    add_bag_render_command(bag_commands)


def cmd_bag_render(args: argparse.Namespace) -> int:
    """One instant of a bag as a viewer shows it, to PNG (glocal_app/bag_render.py); exit code 1 on a bag that
    lacks what a viewer needs."""
    from glocal_app.bag_render import cmd_bag_render as render

    return render(args)


def add_bag_render_command(bag_commands: argparse._SubParsersAction) -> None:
    """``glocal-ros bag render``."""
    render = bag_commands.add_parser(
        "render", help="one instant of a bag as a viewer shows it (robot_description, TF, the object marker), "
                       "to PNG; --sim-out: the sim's own image of it")
    render.add_argument("bag", type=Path, help="rosbag2 directory")
    render.add_argument("--out", type=Path, required=True, metavar="PNG", help="the rendered frame")
    when = render.add_mutually_exclusive_group()
    when.add_argument("--time", type=float, metavar="SECONDS",
                      help="the /tf stamp nearest this many seconds after the first /tf stamp "
                           "(default: the middle /tf stamp)")
    when.add_argument("--stamp", type=int, metavar="NANOSECONDS", help="exactly this /tf header stamp")
    render.add_argument("--sim-out", type=Path, metavar="PNG",
                        help="also the sim's own camera image of the same instant (its bodies set to the recorded "
                             "joint states and object pose), with the same camera")
    render.add_argument("--width", type=int, default=640, help="pixels (default 640)")
    render.add_argument("--height", type=int, default=480, help="pixels (default 480)")
    render.add_argument("--namespace", metavar="NS",
                        help="the robot's namespace in the bag (default: the one its viewer topics are recorded "
                             "under)")
    render.add_argument("--objects-dir", type=Path, metavar="DIR",
                        help="with --sim-out: where <TASK>/model.urdf lives (default: the package's assets)")
    render.set_defaults(func=cmd_bag_render)
