"""A node's parameters from its declaration (``parameter_specs``): descriptors, checks, callbacks.

:class:`NodeParameters` turns a :class:`~hexapod_vibration.parameter_specs.NodeSpec` into
rclpy parameters, in the way of generate_parameter_library:

- each parameter is declared with a ``ParameterDescriptor`` made from its spec
  (:func:`descriptor_for`): description with the unit, the true range (a closed range as
  ``floating_point_range``/``integer_range``, which rclpy enforces; open bounds, element
  ranges, lengths and choices in ``additional_constraints``), read-only;
- the start-up values are validated exactly as a run-time change is (the spec's checks,
  parameter by parameter and together, then the node's own check), and refused with a
  one-line reason (``ValueError``) before the node does anything;
- parameters given to the node that it does not declare are reported (a warning naming
  them);
- at run time the on-set callback only validates; the post-set callback (rclpy's
  ``add_post_set_parameters_callback``, as in ros2/demos) applies. A pre-set callback gives
  an empty array the declared array type: ``ros2 param set ... "[]"`` and ``ros2 param
  load`` of a dumped ``[]`` send a typeless empty list, which rclpy reads as a bool array.

The helpers below the class (``declare_float`` ...) are the older one-call declarations,
still used by the notch controller until it moves to its spec.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from hexapod_vibration.parameter_specs import RCLPY_PARAMETERS, NodeSpec, ParameterSpec
from hexapod_vibration.ros.rclpy_internals import parameter_overrides

NodeCheck = Callable[[Mapping[str, Any], frozenset], str]
"""A node's own check of its parameters (values after the change, names changed): reason or ''."""
Apply = Callable[[dict[str, Any]], None]
"""Applies accepted changes ``{name: value}`` (post-set)."""

_TYPES = {
    "bool": Parameter.Type.BOOL, "int": Parameter.Type.INTEGER,
    "double": Parameter.Type.DOUBLE, "string": Parameter.Type.STRING,
    "int[]": Parameter.Type.INTEGER_ARRAY, "double[]": Parameter.Type.DOUBLE_ARRAY,
    "string[]": Parameter.Type.STRING_ARRAY,
}
_ARRAY_TYPES = frozenset({
    Parameter.Type.BYTE_ARRAY, Parameter.Type.BOOL_ARRAY, Parameter.Type.INTEGER_ARRAY,
    Parameter.Type.DOUBLE_ARRAY, Parameter.Type.STRING_ARRAY,
})


def descriptor_for(spec: ParameterSpec) -> ParameterDescriptor:
    """The ``ParameterDescriptor`` of a parameter spec, stating its true range.

    A scalar range with closed ends becomes ``floating_point_range``/``integer_range``
    (``ros2 param describe`` shows it as Min/Max, rclpy enforces it); everything the ROS
    ranges cannot say exactly (an open end, element ranges, lengths, choices, joint
    constraints) is written out in ``additional_constraints``.
    """
    description = f"{spec.description} ({spec.unit})" if spec.unit else spec.description
    descriptor = ParameterDescriptor(
        type=_TYPES[spec.type].value, description=description, read_only=spec.read_only,
        additional_constraints=spec.range_text())
    closed = not (spec.low_open or spec.high_open)
    bounded = spec.low is not None or spec.high is not None
    if spec.type == "double" and bounded and closed:
        descriptor.floating_point_range = _float_range(spec.low, spec.high)
    elif spec.type == "int" and bounded and closed:
        low = -(2**63) if spec.low is None else int(spec.low)
        high = 2**63 - 1 if spec.high is None else int(spec.high)
        descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=0)]
    return descriptor


def _plain(value: Any) -> Any:
    """A parameter value as plain Python (arrays as lists)."""
    if isinstance(value, (str, bytes, bool, int, float)) or value is None:
        return value
    return list(value)


class NodeParameters:
    """The declared parameters of one node (see the module docstring)."""

    def __init__(self, node: Node, spec: NodeSpec) -> None:
        """Declare every parameter of ``spec`` on ``node`` (start-up values: overrides).

        Raises:
            ValueError: a start-up value is refused (wrong type, out of range, ...); the
                message is one line naming the parameter.
        """
        self.node = node
        self.spec = spec
        self._check: NodeCheck | None = None
        self._apply: Apply | None = None
        for parameter in spec.parameters:
            self._declare(parameter)
        reason = spec.check(self.values())
        if reason:
            raise ValueError(reason)    # exactly the reason a run-time change would get
        self.unknown = self._report_unknown()

    def _declare(self, spec: ParameterSpec) -> None:
        descriptor = descriptor_for(spec)
        try:
            if spec.is_array:
                _declare_array(self.node, spec.name, list(spec.default), descriptor,
                               _TYPES[spec.type])
            else:
                self.node.declare_parameter(spec.name, spec.default, descriptor)
        except InvalidParameterValueException as exc:   # the reason a run-time set gets
            reason = str(exc.args[0]).split("Reason: ", 1)[-1].removesuffix(f": {spec.name}")
            raise ValueError(_naming(spec.name, reason)) from None
        except InvalidParameterTypeException:
            given = parameter_overrides(self.node)[spec.name].type_
            reason = (f"Wrong parameter type, expected '{Parameter.Type(descriptor.type)}' "
                      f"got '{given}'")                 # rclpy's run-time wording
            raise ValueError(_naming(spec.name, reason)) from None
        except ParameterException as exc:
            raise ValueError(_naming(spec.name, _one_line(exc))) from None

    def _report_unknown(self) -> list[str]:
        """Warn about parameters given to the node (CLI, params file) that it does not have."""
        unknown = sorted(name for name in parameter_overrides(self.node)
                         if name not in self.spec.by_name and name not in RCLPY_PARAMETERS
                         and not name.startswith("qos_overrides."))
        if unknown:
            self.node.get_logger().warn(
                f"unknown parameter(s) ignored: {', '.join(unknown)} (this node has: "
                f"{', '.join(self.spec.names)})")
        return unknown

    def values(self) -> dict[str, Any]:
        """Every parameter of the spec at its current value (arrays as lists)."""
        return {name: _plain(parameter_value(self.node, name)) for name in self.spec.names}

    def __getitem__(self, name: str) -> Any:
        """Current value of one parameter."""
        return _plain(parameter_value(self.node, name))

    def serve(self, check: NodeCheck | None = None, apply: Apply | None = None) -> None:
        """Validate the start-up values with ``check`` too, then serve run-time changes.

        Raises:
            ValueError: the node's own check refuses the start-up values.
        """
        self._check = check
        self._apply = apply
        reason = check(self.values(), frozenset(self.spec.names)) if check else ""
        if reason:
            raise ValueError(reason)
        self.node.add_pre_set_parameters_callback(self._typed_empty_arrays)
        self.node.add_on_set_parameters_callback(self._validate)
        self.node.add_post_set_parameters_callback(self._applied)

    def validate(self, changes: Mapping[str, Any]) -> str:
        """Why ``changes`` would be refused, or ``''``: exactly the start-up validation."""
        values = {**self.values(), **{k: _plain(v) for k, v in changes.items()}}
        reason = self.spec.check(values, list(changes))
        if not reason and self._check is not None:
            reason = self._check(values, frozenset(changes))
        return reason

    def _typed_empty_arrays(self, params: list[Parameter]) -> list[Parameter]:
        typed = []
        for param in params:
            spec = self.spec.by_name.get(param.name)
            if (spec is not None and spec.is_array and param.type_ in _ARRAY_TYPES
                    and len(param.value) == 0):
                param = Parameter(param.name, _TYPES[spec.type], [])
            typed.append(param)
        return typed

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        reason = self.validate({q.name: q.value for q in params if q.name in self.spec.by_name})
        return reject(reason) if reason else accept()

    def _applied(self, params: list[Parameter]) -> None:
        changes = {q.name: _plain(q.value) for q in params if q.name in self.spec.by_name}
        if not changes or self._apply is None:
            return
        try:
            self._apply(changes)
        except Exception as exc:   # validated: a failure here is a bug, never fatal
            self.node.get_logger().error(f"applying {sorted(changes)} failed: {exc!r}")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _naming(name: str, reason: str) -> str:
    """``reason`` in one line, prefixed with the parameter's name unless it names it."""
    reason = " ".join(reason.split())
    return reason if name in reason else f"parameter {name}: {reason}"


def descriptor(description: str, read_only: bool = False) -> ParameterDescriptor:
    """A plain descriptor (for types the helpers below do not cover)."""
    return ParameterDescriptor(description=description, read_only=read_only)


def _descriptor(
    param_type: int, description: str, read_only: bool, additional_constraints: str = ""
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
    low = float("-inf") if min_value is None else float(min_value)
    high = float("inf") if max_value is None else float(max_value)
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
            raise ValueError(f"{name}: cannot set an empty array ({result.reason})")
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
    constraints = f'one of: {", ".join(choices)}' if choices else ""
    descriptor = _descriptor(ParameterType.PARAMETER_STRING, description, read_only, constraints)
    value = str(node.declare_parameter(name, str(default), descriptor).value)
    reason = check_choice(name, value, choices)
    if reason:
        raise ValueError(reason)
    return value


def _bounds_text(min_value: float | None, max_value: float | None) -> str:
    """Human-readable element bounds for ``additional_constraints``."""
    if min_value is None and max_value is None:
        return ""
    low = "-inf" if min_value is None else f"{min_value:g}"
    high = "inf" if max_value is None else f"{max_value:g}"
    return f"every element in [{low}, {high}]"


def check_float_array(
    name: str, values: Sequence[float], min_value: float | None, max_value: float | None
) -> str:
    """Return why ``values`` violates the element bounds, or ``''`` when it does not."""
    for i, value in enumerate(values):
        if min_value is not None and value < min_value:
            return f"{name}[{i}] = {value:g} is below the minimum {min_value:g}"
        if max_value is not None and value > max_value:
            return f"{name}[{i}] = {value:g} is above the maximum {max_value:g}"
    return ""


def check_choice(name: str, value: str, choices: Sequence[str] | None) -> str:
    """Return why ``value`` is not one of ``choices``, or ``''`` when it is (or no choices)."""
    if choices and value not in choices:
        return f'{name} = {value!r} is not one of: {", ".join(choices)}'
    return ""


def accept() -> SetParametersResult:
    """Result accepting a set-parameters request."""
    return SetParametersResult(successful=True, reason="")


def reject(reason: str) -> SetParametersResult:
    """Result rejecting a set-parameters request; ``reason`` is shown to the caller."""
    return SetParametersResult(successful=False, reason=reason)


def parameter_value(node: Node, name: str) -> Any:
    """Current value of a declared parameter (Python type: float, list, bool, str, ...).

    A parameter declared by type only that was never set reads as ``None`` instead of
    raising (the array helpers above never leave one unset: they read as ``[]``).
    """
    if not node.has_parameter(name):
        raise KeyError(f"parameter {name!r} is not declared")
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None
