"""Helpers for the tests that run the three nodes as processes (imported, not collected).

Recorders of the ``/pph/*`` topics keyed by the in-band sample index, the latest
``/diagnostics`` status of every node, a blocking wrapper around rclpy's parameter client
(the services ``ros2 param`` uses) and a least-squares tone amplitude. Nothing here
measures or asserts time: every wait has a generous hang guard only.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from hexapod_vibration.cdr import decode_strut_cdr
from hexapod_vibration.contract import SAMPLE_RATE_HZ, InvalidStrutMessage
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS
from hexapod_vibration.ros.rclpy_internals import take_serialized_batch
from hexapod_vibration.ros.service_handshake import shake_hands

HANG_GUARD_S = 180.0
"""Longest wait for anything (s): a guard against hangs, never a timing requirement (90 s
was too short once on CI: the composed graph ran its 6000 lockstep samples at 65/s while
the other worker ran a graph test)."""

FS_HZ = SAMPLE_RATE_HZ
TAKE_BATCH = 1000
"""Messages taken from one subscription per callback."""

RECORD_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=20000,
    durability=DurabilityPolicy.VOLATILE,
)
"""Test-side subscriptions: deep enough that a busy test process loses nothing it needs."""

STRUT_TOPICS = ("/pph/accel", "/pph/eddy", "/pph/notch_command", "/pph/pointing_command",
                "/pph/actuator_force")


class StrutTopic:
    """Everything received on one ``/pph/*`` topic, by sample index (and by run).

    The subscription is raw and each callback takes every message already queued (as the
    recorder does): one executor dispatch per message would fall far behind the loop on a
    loaded machine.
    """

    def __init__(self, node: Node, topic: str):
        self.topic = topic
        self.by_index: dict[int, np.ndarray] = {}
        self.by_run: dict[int | None, dict[int, np.ndarray]] = {}
        self.last_index = -1
        """Highest sample index received, -1 before any."""
        self.first_message: Float64MultiArray | None = None
        self.messages = 0
        self.unindexed = 0
        self.invalid = 0
        self.subscription = node.create_subscription(
            Float64MultiArray, topic, self._on_message, RECORD_QOS, raw=True)

    def _on_message(self, raw: bytes) -> None:
        self._record(raw)
        for more in take_serialized_batch(self.subscription, TAKE_BATCH):
            self._record(more)

    def _record(self, raw: bytes) -> None:
        try:
            values, index, run = decode_strut_cdr(raw)
        except InvalidStrutMessage:     # e.g. what a test itself sends to a node
            self.invalid += 1
            return
        self.messages += 1
        if self.first_message is None:
            self.first_message = deserialize_message(raw, Float64MultiArray)
        if index is None:
            self.unindexed += 1
            return
        self.by_index[index] = np.array(values)
        self.by_run.setdefault(run, {})[index] = self.by_index[index]
        self.last_index = max(self.last_index, index)

    def window(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(indices, values (n, 6)) received for start <= index < stop."""
        idx = [i for i in range(max(start, 0), stop) if i in self.by_index]
        values = np.array([self.by_index[i] for i in idx]).reshape(-1, 6)
        return np.array(idx, dtype=int), values

    def latest(self, samples: int) -> np.ndarray:
        """Values (n, 6) of the last ``samples`` sample indices (those received)."""
        return self.window(self.last_index - samples + 1, self.last_index + 1)[1]


class ClockTopic:
    """Sim times received on /clock (ns)."""

    def __init__(self, node: Node):
        self.times_ns: list[int] = []
        qos = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                         history=HistoryPolicy.KEEP_LAST, depth=1000)
        node.create_subscription(Clock, "/clock", self._on_clock, qos)

    def _on_clock(self, msg: Clock) -> None:
        self.times_ns.append(msg.clock.sec * 1_000_000_000 + msg.clock.nanosec)


class Diagnostics:
    """Latest ``/diagnostics`` status of each status name, and every status received."""

    def __init__(self, node: Node):
        self.latest: dict[str, Any] = {}
        self.history: list[Any] = []
        # a deep queue: a listener starved by a loaded machine must not lose one node's
        # status under another's (the composed graph's notch status never arrived on CI)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag,
                                 QoSProfile(reliability=DIAGNOSTICS_QOS.reliability,
                                            history=DIAGNOSTICS_QOS.history, depth=1000,
                                            durability=DIAGNOSTICS_QOS.durability))

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            self.latest[status.name] = status
            self.history.append(status)

    def values(self, name: str) -> dict[str, str]:
        """Key/values of the latest status called ``name`` ({} before any)."""
        status = self.latest.get(name)
        return {} if status is None else {kv.key: kv.value for kv in status.values}

    def history_values(self, name: str) -> list[dict[str, str]]:
        """Key/values of every status called ``name`` received, oldest first."""
        return [{kv.key: kv.value for kv in st.values} for st in self.history if st.name == name]

    def value(self, name: str, key: str, default: str = "") -> str:
        return self.values(name).get(key, default)

    def int_value(self, name: str, key: str) -> int:
        return int(self.value(name, key, "-1"))


class RecorderStatus:
    """Latest status the recorder published on /diagnostics (subscribed on ``node``)."""

    def __init__(self, node: Node):
        self.values: dict[str, str] = {}
        node.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics,
                                 DIAGNOSTICS_QOS)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith("pph_recorder"):
                self.values = {kv.key: kv.value for kv in status.values}

    def count(self, key: str) -> int:
        return int(self.values.get(key, "0"))


def drain(ros_context, budget_s: float = 0.05) -> None:
    """Run ready callbacks without waiting, for ``budget_s`` of wall time.

    One callback per spin and a predicate evaluated between spins would fall far behind
    a few 1 kHz streams on a loaded machine.
    """
    deadline = time.monotonic() + budget_s
    while time.monotonic() < deadline:
        ros_context.executor.spin_once(timeout_sec=0.0)


PROGRESS_CHUNK_S = 60.0
"""With a ``progress`` reading, :func:`wait_until` fails only after this long without it
changing (s)."""


def wait_until(ros_context, predicate, timeout_s: float = HANG_GUARD_S, step=None,
               progress=None) -> bool:
    """Spin (draining the queues) until ``predicate()``; False after the hang guard.

    ``step`` (e.g. publishing something) runs before each drain. ``progress`` (e.g. the
    driver's sample count): the guard is a stall, not a total time, so a loop slowed by a
    loaded machine keeps the wait alive while it moves (``PROGRESS_CHUNK_S`` without change
    is a hang).
    """
    def spin() -> None:
        if step is not None:
            step()
        drain(ros_context)
    if progress is None:
        return ros_context.wait_for(predicate, timeout_s, step=spin)
    last = object()
    while True:
        if ros_context.wait_for(predicate, PROGRESS_CHUNK_S, step=spin):
            return True
        now = progress()
        if now == last:
            return False
        last = now


class ParameterClient:
    """Blocking calls of a node's parameter services (what ``ros2 param`` calls)."""

    def __init__(self, ros_context, node: Node, target: str):
        self.ros_context = ros_context
        self.target = target
        self.client = AsyncParameterClient(node, target)
        assert self.client.wait_for_services(timeout_sec=HANG_GUARD_S), f"{target}: no services"
        silent = shake_hands(self.client,
                             lambda t: ros_context.executor.spin_once(timeout_sec=t), HANG_GUARD_S)
        assert not silent, f"{target}: {silent} did not answer"

    def _wait(self, future):
        assert wait_until(self.ros_context, future.done), f"{self.target}: no answer"
        return future.result()

    def names(self) -> list[str]:
        return list(self._wait(self.client.list_parameters()).result.names)

    def get(self, *names: str) -> dict[str, Any]:
        values = self._wait(self.client.get_parameters(list(names))).values
        assert len(values) == len(names), f"{self.target}: get_parameters({names}) failed"
        return {n: _python(v) for n, v in zip(names, values, strict=True)}

    def get_all(self) -> dict[str, Any]:
        return self.get(*self.names())

    def set(self, name: str, value: Any) -> SetParametersResult:
        """Set one parameter (``ros2 param set``); the node's result (successful, reason)."""
        param = value if isinstance(value, Parameter) else Parameter(name, value=value)
        results = self._wait(self.client.set_parameters([param])).results
        assert len(results) == 1
        return results[0]

    def set_atomically(self, **values: Any) -> SetParametersResult:
        params = [Parameter(n, value=v) for n, v in values.items()]
        return self._wait(self.client.set_parameters_atomically(params)).result


def _python(value) -> Any:
    result = parameter_value_to_python(value)
    if isinstance(result, (list, tuple)) or type(result).__name__ == "array":
        return list(result)
    return result


def tone_amplitude(indices: np.ndarray, values: np.ndarray, frequency_hz: float,
                   fs: float = FS_HZ) -> np.ndarray:
    """Per-column amplitude of a ``frequency_hz`` sinusoid, least squares on the indices.

    The fit has an offset and a slope too (DC, gravity and slow drift removed), and works
    on samples with gaps since every value is placed on its sample index.
    """
    t = np.asarray(indices, float)
    phase = 2.0 * np.pi * frequency_hz * t / fs
    basis = np.column_stack([np.ones_like(t), (t - t.mean()) / max(np.ptp(t), 1.0),
                             np.cos(phase), np.sin(phase)])
    coef, *_ = np.linalg.lstsq(basis, np.asarray(values, float), rcond=None)
    return np.hypot(coef[2], coef[3])


def db(ratio: float | np.ndarray) -> float | np.ndarray:
    return 20.0 * np.log10(ratio)


def assert_rejected(result: SetParametersResult, *words: str) -> None:
    """The set was refused with a non-empty reason containing ``words``."""
    assert not result.successful, "accepted, expected a rejection"
    assert result.reason.strip(), "rejected without a reason"
    for word in words:
        assert word.lower() in result.reason.lower(), result.reason


def assert_close(actual: Any, expected: Any) -> None:
    if isinstance(expected, float) and math.isnan(expected):
        assert math.isnan(actual)
    elif isinstance(expected, Sequence) and not isinstance(expected, str):
        assert list(actual) == list(expected), (actual, expected)
    else:
        assert actual == expected, (actual, expected)


def run_experiment(env, scenario, out, *extra, timeout: float = 400.0
                   ) -> subprocess.CompletedProcess:
    """``experiment --scenario SCENARIO --out OUT [extra]`` in a child process (text output)."""
    cmd = [sys.executable, "-m", "hexapod_vibration.tools.experiment", "--scenario", str(scenario),
           "--out", str(out), *extra]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)


def float64_array(data, dims) -> Float64MultiArray:
    """A Float64MultiArray of ``data`` with ``layout.dim`` from (label, size, stride) triples."""
    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label=lbl, size=size, stride=stride) for lbl, size, stride in dims
    ]
    msg.data = [float(x) for x in data]
    return msg


def start_pointing_loop(node_processes, *driver_args: str) -> tuple:
    """A lockstep driver that waits for the pointing controller only, and that controller.

    ``driver_args``: more ``-p name:=value`` arguments of the driver. Returns (driver,
    pointing) processes.
    """
    driver = node_processes.start("pph_driver", "--ros-args", "-p",
                                  "lockstep_controllers:=[pointing]", *driver_args)
    return driver, node_processes.start("pointing_controller")
