"""Minimal stand-ins of ROS 2's ``launch`` and ``launch_ros`` modules, for testing launch files here.

``launch`` and ``launch_ros`` are not on PyPI, so the venv cannot run
``ros2 launch``. These classes take exactly the constructor arguments of the
Jazzy classes they stand for (keyword-only where those are; the signatures
were copied from ros2/launch and ros2/launch_ros, branch jazzy), keep them
for the test to inspect, and refuse what the real ones refuse at construction
or execution (a default or a value outside ``choices``, a non-callable
function, a parameter file that does not exist). ``evaluate`` does what
``ros2 launch`` does with a description before anything starts: arguments
into launch configurations, checked against the declarations, then every
``OpaqueFunction`` called with the context.

``install(modules)`` puts them into a ``sys.modules``-like mapping (pytest's
``monkeypatch.setitem`` or a subprocess's own ``sys.modules``).
"""

from __future__ import annotations

import os
import types
from typing import Any, Callable, Iterable, MutableMapping

#: ExecuteProcess/ExecuteLocal keyword arguments a Node passes on (launch, jazzy).
EXECUTE_KWARGS = {"output", "emulate_tty", "respawn", "respawn_delay", "respawn_max_retries", "sigterm_timeout",
                  "sigkill_timeout", "cached_output", "log_cmd", "on_exit", "prefix", "cwd", "env", "additional_env",
                  "shell", "condition"}
OUTPUTS = {"screen", "log", "both", "own_log"}


class LaunchDescription:
    def __init__(self, initial_entities: Iterable[Any] | None = None) -> None:
        self.entities = list(initial_entities or [])


class DeclareLaunchArgument:
    def __init__(self, name: str, *, default_value: str | None = None, description: str | None = None,
                 choices: list[str] | None = None, **kwargs) -> None:
        assert not kwargs, kwargs
        if choices is not None and default_value is not None and default_value not in choices:
            raise RuntimeError(f"default {default_value!r} of {name} is not one of {choices}")
        self.name, self.default_value, self.description, self.choices = name, default_value, description, choices


class OpaqueFunction:
    def __init__(self, *, function: Callable, args: Iterable[Any] | None = None,
                 kwargs: dict[str, Any] | None = None) -> None:
        if not callable(function):
            raise TypeError(f"OpaqueFunction expected a callable for 'function', got {type(function)}")
        self.function, self.args, self.kwargs = function, list(args or []), dict(kwargs or {})


class RegisterEventHandler:
    def __init__(self, event_handler: Any) -> None:
        self.event_handler = event_handler


class EmitEvent:
    def __init__(self, *, event: Any) -> None:
        if not isinstance(event, Shutdown):  # the only event these stand-ins know
            raise RuntimeError(f"EmitEvent() expected an event instance, got {event!r}")
        self.event = event


class OnProcessExit:
    def __init__(self, *, target_action: Any = None, on_exit: Any) -> None:
        self.target_action, self.on_exit = target_action, on_exit


class Shutdown:
    def __init__(self, *, reason: str = "reason not given", due_to_sigint: bool = False) -> None:
        self.reason, self.due_to_sigint = reason, due_to_sigint


class Node:
    """launch_ros.actions.Node: what it would start, kept as given."""

    def __init__(self, *, executable: str, package: str | None = None, name: str | None = None,
                 namespace: str | None = None, exec_name: str | None = None, parameters: list | None = None,
                 remappings: list | None = None, ros_arguments: list | None = None, arguments: list | None = None,
                 **kwargs) -> None:
        unknown = set(kwargs) - EXECUTE_KWARGS
        if unknown:
            raise TypeError(f"Node() got unexpected keyword arguments {sorted(unknown)}")
        if "output" in kwargs and kwargs["output"] not in OUTPUTS:
            raise ValueError(f"output={kwargs['output']!r}")
        for entry in parameters or []:
            if isinstance(entry, dict):
                bad = {key: value for key, value in entry.items()
                       if not isinstance(value, (str, int, float, bool, list))}
                assert not bad, f"parameter values launch_ros cannot pass: {bad}"
            else:
                assert os.path.isfile(entry), f"parameter file {entry} does not exist"
        for rule in remappings or []:
            assert isinstance(rule, tuple) and len(rule) == 2 and all(isinstance(part, str) for part in rule), rule
        self.package, self.executable, self.name, self.namespace = package, executable, name, namespace
        self.exec_name, self.parameters, self.remappings = exec_name, list(parameters or []), list(remappings or [])
        self.ros_arguments, self.arguments, self.kwargs = ros_arguments, arguments, kwargs


class LaunchContext:
    def __init__(self, launch_configurations: dict[str, str]) -> None:
        self.launch_configurations = launch_configurations


def evaluate(description: LaunchDescription, **arguments: str) -> list:
    """What ``ros2 launch FILE name:=value ...`` would execute, once arguments are resolved.

    Unknown or missing arguments and values outside ``choices`` are refused, as launch refuses them.
    Returns the description's other entities, each ``OpaqueFunction`` replaced by what it returned.
    """
    declared = {e.name: e for e in description.entities if isinstance(e, DeclareLaunchArgument)}
    unknown = set(arguments) - set(declared)
    if unknown:
        raise KeyError(f"undeclared launch arguments {sorted(unknown)}")
    configurations: dict[str, str] = {}
    for name, declaration in declared.items():
        value = arguments.get(name, declaration.default_value)
        if value is None:
            raise RuntimeError(f"required launch argument {name} was not given")
        if declaration.choices is not None and value not in declaration.choices:
            raise RuntimeError(f"argument {name}:={value!r} is not one of {declaration.choices}")
        configurations[name] = value
    context = LaunchContext(configurations)
    executed: list = []
    for entity in description.entities:
        if isinstance(entity, OpaqueFunction):
            executed += list(entity.function(context, *entity.args, **entity.kwargs) or [])
        elif not isinstance(entity, DeclareLaunchArgument):
            executed.append(entity)
    return executed


def modules() -> dict[str, types.ModuleType]:
    """The stand-in modules by name: launch, launch.actions, ..., launch_ros.actions."""
    contents = {
        "launch": {"LaunchDescription": LaunchDescription, "LaunchContext": LaunchContext},
        "launch.actions": {"DeclareLaunchArgument": DeclareLaunchArgument, "OpaqueFunction": OpaqueFunction,
                           "RegisterEventHandler": RegisterEventHandler, "EmitEvent": EmitEvent},
        "launch.event_handlers": {"OnProcessExit": OnProcessExit},
        "launch.events": {"Shutdown": Shutdown},
        "launch_ros": {},
        "launch_ros.actions": {"Node": Node},
    }
    built = {}
    for name, attributes in contents.items():
        module = types.ModuleType(name, f"stand-in of {name} (test/launch_standins.py)")
        module.__dict__.update(attributes)
        built[name] = module
    for name, module in built.items():  # submodules as attributes, as `import launch.actions` leaves them
        parent, _, child = name.rpartition(".")
        if parent:
            setattr(built[parent], child, module)
    return built


def install(target: MutableMapping[str, Any],
            setitem: Callable[[MutableMapping, str, Any], None] | None = None) -> None:
    """Put the stand-ins into ``target`` (e.g. ``sys.modules``), through ``setitem`` when given (monkeypatch)."""
    for name, module in modules().items():
        if setitem is None:
            target[name] = module
        else:
            setitem(target, name, module)
