"""Declaring parameters with descriptors, in one line each."""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    *,
    min_value: float | int | None = None,
    max_value: float | int | None = None,
    read_only: bool = True,
) -> Any:
    """Declare ``name`` with a description (and a range for numbers); return its value.

    Parameters are read-only by default: the nodes read them at start-up, so a
    later ``ros2 param set`` would silently do nothing.
    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    if min_value is not None or max_value is not None:
        if isinstance(default, bool):
            raise TypeError(f"parameter {name}: a range makes no sense for a bool")
        if isinstance(default, int):
            descriptor.integer_range = [
                IntegerRange(from_value=int(min_value), to_value=int(max_value), step=0)
            ]
        else:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(min_value), to_value=float(max_value), step=0.0)
            ]
    return node.declare_parameter(name, default, descriptor).value
