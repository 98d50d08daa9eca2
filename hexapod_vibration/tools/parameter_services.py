"""Blocking calls of one node's parameter services, from a private rclpy context.

What ``hexapod_param`` (``tools/hexapod_param.py``) runs once its command line is good: the
requests ``ros2 param`` sends (list, get, describe, set; ``load`` as one SetParameters
request that the node applies one parameter at a time), each waited for at most the
given timeout. Values are fitted to the declared type first (:func:`fit_value`).
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import rclpy
import yaml
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.signals import SignalHandlerOptions

from hexapod_vibration.ros.service_handshake import answer_with_resends, shake_hands

_ARRAYS = {ParameterType.PARAMETER_BYTE_ARRAY, ParameterType.PARAMETER_BOOL_ARRAY,
           ParameterType.PARAMETER_INTEGER_ARRAY, ParameterType.PARAMETER_DOUBLE_ARRAY,
           ParameterType.PARAMETER_STRING_ARRAY}


class Refused(Exception):
    """The node answered no, or has no such parameter (the message is one line)."""


class Unreachable(Exception):
    """The node's parameter services did not answer in time."""


def closest(name: str, names: Sequence[str]) -> str:
    """`` (did you mean x?)`` for the nearest of ``names``, or ``''``."""
    match = difflib.get_close_matches(name, names, n=1)
    return f" (did you mean {match[0]}?)" if match else ""


def _as_float(value: Any) -> float | None:
    """``value`` as a float when it is a number or a word that reads as one (``1e-3``)."""
    if isinstance(value, bool):
        return None
    try:
        return float(value) if isinstance(value, (int, float, str)) else None
    except ValueError:
        return None


def fit_value(value: Any, declared: int, text: str | None = None) -> Any:
    """``value`` (parsed as YAML) in the declared type where the meaning is plain.

    An integer or a number YAML read as a word (``1e-3``; YAML 1.1 wants ``1.0e-3``) for a
    double, such numbers for a double array, an empty list for any array, the typed
    ``text`` for a string; anything else is returned as it is, for the node to accept or
    refuse with its reason.
    """
    if declared == ParameterType.PARAMETER_DOUBLE and _as_float(value) is not None:
        return _as_float(value)
    if declared in _ARRAYS and isinstance(value, list) and not value:
        return []
    if declared == ParameterType.PARAMETER_DOUBLE_ARRAY and isinstance(value, list):
        numbers = [_as_float(v) for v in value]
        return value if None in numbers else numbers
    if declared == ParameterType.PARAMETER_STRING and not isinstance(value, str):
        return text if text is not None else value
    return value


def _parameter(name: str, value: Any, declared: int, text: str | None = None) -> Parameter:
    """The request's parameter: of the declared type when ``value`` fits it, else as typed.

    A value of another type goes as its own type (the node refuses it with its reason);
    one rclpy cannot type (a list of mixed types) goes as its text, as ``ros2 param set``
    sends it.
    """
    for kind in (Parameter.Type(declared), None):
        try:
            return Parameter(name, kind, value)
        except (TypeError, ValueError):
            continue
    return Parameter(name, Parameter.Type.STRING, text if text is not None else str(value))


def _plain(value: Any) -> Any:
    """A parameter value as plain Python (arrays as lists)."""
    if isinstance(value, (str, bool, int, float)) or value is None:
        return value
    return list(value)


class ParameterServices:
    """A client of ``target``'s parameter services (``with``: connect, then shut down).

    ``timeout_s``: how long to wait for the services (discovery, s); ``answer_timeout_s``:
    for each answer (s).
    """

    def __init__(self, target: str, timeout_s: float, answer_timeout_s: float) -> None:
        """Start a private rclpy context (no signal handlers: ``cli``'s stop handlers rule)."""
        self.target = target
        self.timeout_s = timeout_s
        self.answer_timeout_s = answer_timeout_s
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f"hexapod_param_{os.getpid()}", context=self.context,
                                      start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.client = AsyncParameterClient(self.node, target)

    def __enter__(self) -> ParameterServices:
        """Wait for the node's parameter services; :class:`Unreachable` after the timeout.

        Requests are then resent until answered, and a set follows a handshake with the set
        service (:mod:`hexapod_vibration.ros.service_handshake`): Fast DDS can lose a
        response to a client it has just discovered.
        """
        if not self.client.wait_for_services(timeout_sec=self.timeout_s):
            self.close()
            raise Unreachable(f"no answer from {self.target} within {self.timeout_s:g} s")
        return self

    def _spin_once(self, timeout_s: float) -> None:
        self.executor.spin_once(timeout_sec=timeout_s)

    def __exit__(self, *exc: object) -> None:
        """Shut the context down."""
        self.close()

    def close(self) -> None:
        """Destroy the node and shut the private context down (idempotent)."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def _call(self, request: Callable[[], Any], name: str) -> Any:
        """The answer to an idempotent ``request`` (resent until answered, see the handshake)."""
        answers = answer_with_resends({name: request}, self._spin_once, self.answer_timeout_s)
        if name not in answers:
            raise Unreachable(f"{self.target} did not answer {name} within "
                              f"{self.answer_timeout_s:g} s")
        return answers[name]

    def _set(self, parameters: list[Parameter]) -> list[Any]:
        """Send one SetParameters request (never resent: the handshake goes first)."""
        silent = shake_hands(self.client, self._spin_once, self.answer_timeout_s,
                             services=("set_parameters",))
        future = self.client.set_parameters(parameters)
        if not silent:
            self.executor.spin_until_future_complete(future, self.answer_timeout_s)
        if silent or not future.done():
            raise Unreachable(f"{self.target} did not answer set_parameters within "
                              f"{self.answer_timeout_s:g} s")
        return list(future.result().results)

    def names(self) -> list[str]:
        """Every parameter name of the node."""
        return list(self._call(self.client.list_parameters, "list_parameters").result.names)

    def _known(self, names: Sequence[str]) -> None:
        """:class:`Refused` naming the first of ``names`` the node does not have."""
        known = self.names()
        for name in names:
            if name not in known:
                raise Refused(f"{self.target} has no parameter {name!r}{closest(name, known)}")

    def get(self, names: Sequence[str]) -> list[Any]:
        """The values of ``names`` (plain Python)."""
        self._known(names)
        values = self._call(lambda: self.client.get_parameters(list(names)),
                            "get_parameters").values
        return [_plain(parameter_value_to_python(v)) for v in values]

    def describe(self, names: Sequence[str]) -> dict[str, ParameterDescriptor]:
        """The descriptors of ``names`` (type, read-only, ranges)."""
        self._known(names)
        descriptors = self._call(lambda: self.client.describe_parameters(list(names)),
                                 "describe_parameters").descriptors
        return dict(zip(names, descriptors, strict=True))

    def set(self, name: str, text: str) -> tuple[Any, Any]:
        """Set ``name`` from its YAML ``text`` (``ros2 param set``).

        Returns:
            The value sent, and the value the node holds when asked right after (a node may
            change it at once, e.g. the notch's guard lowering ``mu``).
        """
        declared = self.describe([name])[name].type
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text                                    # a word, as ros2 param types it
        parameter = _parameter(name, fit_value(value, declared, text), declared, text)
        result = self._set([parameter])[0]
        if not result.successful:
            raise Refused(f"{self.target} refused {name} = {text}: "
                          f"{' '.join(result.reason.split()) or 'no reason given'}")
        return _plain(parameter.value), self.get([name])[0]

    def load(self, values: Mapping[str, Any]) -> list[str]:
        """Set every writable one of ``values`` in one request; the read-only names skipped."""
        descriptors = self.describe(list(values))
        skipped = [n for n, d in descriptors.items() if d.read_only]
        parameters = [_parameter(n, fit_value(v, descriptors[n].type), descriptors[n].type)
                      for n, v in values.items() if n not in skipped]
        results = self._set(parameters)
        refused = [f"{p.name}: {' '.join(r.reason.split())}"
                   for p, r in zip(parameters, results, strict=True) if not r.successful]
        if refused:
            raise Refused(f"{self.target} refused {len(refused)} of {len(parameters)} "
                          f"parameter(s): {'; '.join(refused)}")
        return skipped
