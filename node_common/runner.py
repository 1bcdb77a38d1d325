"""Start-up and clean shutdown shared by every node's ``main``."""

from __future__ import annotations

import os
import signal
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from glocal_ros.paths import assets_dir

#: The graph stays on this host unless the user opts in, e.g. with
#: ``export ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (see README, "Networking").
DEFAULT_DISCOVERY_RANGE = "LOCALHOST"
#: Fast DDS 2.x (Jazzy) reads its XML profiles from this variable (3.x also reads FASTDDS_...).
PROFILES_FILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
SHUTDOWN_POLL_SEC = 0.25


def loopback_profile() -> Path:
    """The Fast DDS profile that binds every UDP socket the node receives on to 127.0.0.1."""
    return assets_dir() / "fastdds" / "loopback.xml"


def configure_discovery() -> None:
    """Keep discovery, and the sockets Fast DDS listens on, on loopback unless the environment says otherwise.

    The discovery range limits whom a node finds, not where it listens: on
    LOCALHOST, Fast DDS still binds its ports to 0.0.0.0 unless a profile says
    otherwise, so the loopback profile comes with it. A profiles file of the
    user's own is left as it is (and is then theirs to bind).
    """
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", DEFAULT_DISCOVERY_RANGE)
    if os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST":
        os.environ.setdefault(PROFILES_FILE_VARIABLE, str(loopback_profile()))


def spin_node(make_node: Callable[[], Node], args: Sequence[str] | None = None, num_threads: int = 1) -> int:
    """Create the node, spin it until SIGINT/SIGTERM, shut down cleanly.

    ``num_threads`` > 1 spins a MultiThreadedExecutor, for nodes whose
    callbacks block on other callbacks of theirs (a service that calls
    services); one thread is cheaper per callback.

    A node with a ``drain()`` method gets to run it on SIGINT/SIGTERM while
    its context is still up (rclpy's own handler would shut the context down
    first, and with it every publisher): what it published last can still
    reach its subscribers. Its signals then raise ``KeyboardInterrupt`` in
    the spinning thread instead.

    Returns the process exit code: 1 when the node failed (the error is
    logged through the node's logger when it exists), else the node's own
    ``exit_code`` attribute if it has one (a node that ends itself), else 0.
    """
    configure_discovery()
    drains = callable(getattr(make_node, "drain", None))
    if drains:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.default_int_handler)
    else:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.ALL)
    node: Node | None = None
    failed = False
    try:
        node = make_node()
        executor = MultiThreadedExecutor(num_threads) if num_threads > 1 else SingleThreadedExecutor()
        executor.add_node(node)
        # A bounded wait instead of executor.spin(): the signal handler's wake-up
        # of a waiting MultiThreadedExecutor is sometimes lost, and the node then
        # never notices SIGTERM (seen here about once in three shutdowns).
        while node.context.ok():
            executor.spin_once(timeout_sec=SHUTDOWN_POLL_SEC)
    except KeyboardInterrupt:
        if drains and node is not None and node.context.ok():
            node.drain()
    except ExternalShutdownException:
        pass
    except Exception as error:  # noqa: BLE001 - the process must report any failure and exit non-zero
        logger = node.get_logger() if node is not None else rclpy.logging.get_logger("glocal_ros")
        if rclpy.ok():
            logger.fatal(f"{type(error).__name__}: {error}")
            failed = True
        else:  # SIGINT/SIGTERM shut the context down while the node was starting: a stop, not a failure
            logger.info(f"stopped while starting ({type(error).__name__}: {error})")
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
    return 1 if failed else getattr(node, "exit_code", 0)


@contextmanager
def spinning_node(name: str, domain_id: int, num_threads: int = 1, namespace: str = "") -> Iterator[Node]:
    """A node on a context of its own, spun in a background thread: for tools that call nodes (the benches,
    the tests); ``num_threads`` > 1 runs callbacks in parallel, as ``spin_node``'s does, and the node's
    relative names resolve in ``namespace`` ("" for none).

    The thread spins with bounded waits, as ``spin_node`` does, never ``executor.spin()``: the same lost
    wake-up would leave it deaf to the stop.
    """
    configure_discovery()
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node(name, context=context, namespace=namespace)
    executor = (MultiThreadedExecutor(num_threads, context=context) if num_threads > 1
                else SingleThreadedExecutor(context=context))
    executor.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [executor.spin_once(0.1) for _ in iter(stop.is_set, True)],
                               daemon=True)
    spinner.start()
    try:
        yield node
    finally:
        stop.set()
        spinner.join(5)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
