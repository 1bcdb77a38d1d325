"""``glocal-ros replay`` and ``glocal-ros bag check|repair``: the command-line side of recorded bags.

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
    """Messages per topic and the episode sequence; exit code 1 when episodes are missing or repeated."""
    from glocal_ros.recording import episode_sequence, message_counts
    from glocal_ros.topics import EPISODES_TOPIC

    counts = message_counts(args.bag)
    width = max((len(topic) for topic in counts), default=0)
    for topic, count in counts.items():
        print(f"{topic:<{width}}  {count:>8}")
    check = episode_sequence(args.bag)
    print(f"{EPISODES_TOPIC}: {check.summary()}")
    return 0 if check.ok else 1


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

    bag = commands.add_parser("bag", help="recorded bags: check (counts, episode gaps), repair (a killed recorder's)")
    bag_commands = bag.add_subparsers(dest="bag_command", required=True)
    check = bag_commands.add_parser("check", help="messages per topic and gaps in the episode seq (exit 1 on gaps)")
    check.add_argument("bag", type=Path, help="rosbag2 directory")
    check.set_defaults(func=cmd_bag_check)
    repair = bag_commands.add_parser("repair", help="recover a killed recorder's bag; the original is kept as "
                                                    "BAG.damaged")
    repair.add_argument("bag", type=Path, help="rosbag2 directory")
    repair.set_defaults(func=cmd_bag_repair)
