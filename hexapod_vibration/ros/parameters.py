"""Helpers to declare ROS parameters with descriptors, and to answer set-parameter requests.

Every parameter of the package is declared with a ``ParameterDescriptor`` carrying its
description (including its unit), its range when it has one, and whether it is read-only,
so that ``ros2 param describe`` documents it and the middleware enforces the range before
the node's own ``on_set_parameters`` callback sees the value.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter


def descriptor(description: str, read_only: bool = False) -> ParameterDescriptor:
    """A plain descriptor (for types the helpers below do not cover)."""
    return ParameterDescriptor(description=description, read_only=read_only)


def _descriptor(
    param_type: int, description: str, read_only: bool, additional_constraints: str = ''
) -> ParameterDescriptor:
    """Build a descriptor with the fields common to all parameter kinds."""
    return ParameterDescriptor(
        type=param_type,
        description=description,
        read_only=read_only,
        additional_constraints=additional_constraints,
    )


def _float_range(min_value: float | None, max_value: float | None) -> list[FloatingPointRange]:
    """A ``FloatingPointRange`` list (empty when unbounded; open ends become +-inf)."""
    if min_value is None and max_value is None:
        return []
    low = float('-inf') if min_value is None else float(min_value)
    high = float('inf') if max_value is None else float(max_value)
    return [FloatingPointRange(from_value=low, to_value=high, step=0.0)]


def declare_float(
    node: Node,
    name: str,
    default: float,
    description: str,
    min_value: float | None = None,
    max_value: float | None = None,
    read_only: bool = False,
) -> float:
    """Declare a double parameter and return its value (override or default).

    Args:
        node: Node that owns the parameter.
        name: Parameter name.
        default: Value when not overridden (launch file, ``--ros-args -p``).
        description: What it is, with its unit, e.g. ``"adaptation rate (1/sample)"``.
        min_value: Inclusive lower bound, or ``None``.
        max_value: Inclusive upper bound, or ``None``.
        read_only: Refuse changes after start-up.
    """
    descriptor = _descriptor(ParameterType.PARAMETER_DOUBLE, description, read_only)
    descriptor.floating_point_range = _float_range(min_value, max_value)
    return float(node.declare_parameter(name, float(default), descriptor).value)


def declare_int(
    node: Node,
    name: str,
    default: int,
    description: str,
    min_value: int | None = None,
    max_value: int | None = None,
    read_only: bool = False,
) -> int:
    """Declare an integer parameter and return its value (override or default).

    Args:
        node: Node that owns the parameter.
        name: Parameter name.
        default: Value when not overridden.
        description: What it is, with its unit.
        min_value: Inclusive lower bound, or ``None`` (then the int64 minimum).
        max_value: Inclusive upper bound, or ``None`` (then the int64 maximum).
        read_only: Refuse changes after start-up.
    """
    descriptor = _descriptor(ParameterType.PARAMETER_INTEGER, description, read_only)
    if min_value is not None or max_value is not None:
        low = -(2**63) if min_value is None else int(min_value)
        high = 2**63 - 1 if max_value is None else int(max_value)
        descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=0)]
    return int(node.declare_parameter(name, int(default), descriptor).value)


def declare_float_array(
    node: Node,
    name: str,
    default: Sequence[float],
    description: str,
    min_value: float | None = None,
    max_value: float | None = None,
    read_only: bool = False,
) -> list[float]:
    """Declare a double-array parameter and return its value as a list of floats.

    The element bounds go into ``additional_constraints`` (ROS ranges apply to scalars
    only): the node's ``on_set_parameters`` callback must check them, e.g. with
    :func:`check_float_array`.

    Args:
        node: Node that owns the parameter.
        name: Parameter name.
        default: Value when not overridden. May be empty (see :func:`_declare_array`).
        description: What it is, with the unit of the elements.
        min_value: Inclusive lower bound of every element, or ``None``.
        max_value: Inclusive upper bound of every element, or ``None``.
        read_only: Refuse changes after start-up.
    """
    constraints = _bounds_text(min_value, max_value)
    descriptor = _descriptor(
        ParameterType.PARAMETER_DOUBLE_ARRAY, description, read_only, constraints
    )
    values = _declare_array(node, name, [float(x) for x in default], descriptor,
                            Parameter.Type.DOUBLE_ARRAY)
    return [float(x) for x in values]


def declare_string_array(
    node: Node, name: str, default: Sequence[str], description: str, read_only: bool = False
) -> list[str]:
    """Declare a string-array parameter (may be empty) and return its value."""
    descriptor = _descriptor(ParameterType.PARAMETER_STRING_ARRAY, description, read_only)
    values = _declare_array(node, name, [str(x) for x in default], descriptor,
                            Parameter.Type.STRING_ARRAY)
    return [str(x) for x in values]


def _declare_array(
    node: Node, name: str, default: list, descriptor: ParameterDescriptor,
    array_type: Parameter.Type,
) -> list:
    """Declare an array parameter whose value may be an empty array of ``array_type``.

    rclpy infers the type of an empty list as a byte array, and an empty list in a params
    file or ``-p name:=[]`` arrives as "not set". Either way the parameter would stay
    declared but unset, and then rclpy's ``get_parameters`` service answers nothing at all
    for a request naming it (``ros2 param get``/``dump`` fail). So the parameter is declared
    by type and, when no value came, explicitly set to an empty array of ``array_type``
    (before the node registers its callbacks; a read-only descriptor is applied after).
    """
    writable = copy.deepcopy(descriptor)
    writable.read_only = False
    value = node.declare_parameter(name, default or array_type, writable).value
    if value is None:
        result = node.set_parameters([Parameter(name, array_type, [])])[0]
        if not result.successful:
            raise ValueError(f'{name}: cannot set an empty array ({result.reason})')
        value = []
    if descriptor.read_only:
        node.set_descriptor(name, descriptor)
    return list(value)


def declare_bool(
    node: Node, name: str, default: bool, description: str, read_only: bool = False
) -> bool:
    """Declare a boolean parameter and return its value (override or default)."""
    descriptor = _descriptor(ParameterType.PARAMETER_BOOL, description, read_only)
    return bool(node.declare_parameter(name, bool(default), descriptor).value)


def declare_string(
    node: Node,
    name: str,
    default: str,
    description: str,
    choices: Sequence[str] | None = None,
    read_only: bool = False,
) -> str:
    """Declare a string parameter and return its value (override or default).

    Args:
        node: Node that owns the parameter.
        name: Parameter name.
        default: Value when not overridden.
        description: What it is.
        choices: Allowed values, or ``None`` for any string. Checked here for the start-up
            value; later changes must be checked by the node (see :func:`check_choice`).
        read_only: Refuse changes after start-up.

    Raises:
        ValueError: The start-up value is not one of ``choices``.
    """
    constraints = f'one of: {", ".join(choices)}' if choices else ''
    descriptor = _descriptor(ParameterType.PARAMETER_STRING, description, read_only, constraints)
    value = str(node.declare_parameter(name, str(default), descriptor).value)
    reason = check_choice(name, value, choices)
    if reason:
        raise ValueError(reason)
    return value


def _bounds_text(min_value: float | None, max_value: float | None) -> str:
    """Human-readable element bounds for ``additional_constraints``."""
    if min_value is None and max_value is None:
        return ''
    low = '-inf' if min_value is None else f'{min_value:g}'
    high = 'inf' if max_value is None else f'{max_value:g}'
    return f'every element in [{low}, {high}]'


def check_float_array(
    name: str, values: Sequence[float], min_value: float | None, max_value: float | None
) -> str:
    """Return why ``values`` violates the element bounds, or ``''`` when it does not."""
    for i, value in enumerate(values):
        if min_value is not None and value < min_value:
            return f'{name}[{i}] = {value:g} is below the minimum {min_value:g}'
        if max_value is not None and value > max_value:
            return f'{name}[{i}] = {value:g} is above the maximum {max_value:g}'
    return ''


def check_choice(name: str, value: str, choices: Sequence[str] | None) -> str:
    """Return why ``value`` is not one of ``choices``, or ``''`` when it is (or no choices)."""
    if choices and value not in choices:
        return f'{name} = {value!r} is not one of: {", ".join(choices)}'
    return ''


def accept() -> SetParametersResult:
    """Result accepting a set-parameters request."""
    return SetParametersResult(successful=True, reason='')


def reject(reason: str) -> SetParametersResult:
    """Result rejecting a set-parameters request; ``reason`` is shown to the caller."""
    return SetParametersResult(successful=False, reason=reason)


def parameter_value(node: Node, name: str) -> Any:
    """Current value of a declared parameter (Python type: float, list, bool, str, ...).

    A parameter declared by type only that was never set reads as ``None`` instead of
    raising (the array helpers above never leave one unset: they read as ``[]``).
    """
    if not node.has_parameter(name):
        raise KeyError(f'parameter {name!r} is not declared')
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None
