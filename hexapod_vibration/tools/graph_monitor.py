"""The experiment runner's own rclpy node: what the graph says, and the parameters it sets.

It follows the driver's sample on ``/diagnostics`` (no 1 kHz ``/clock`` reader: a wake-up
per sample, taken from the loop's two cores) and every node's status,
tells when the graph is discovered and matched and when the recorder has written every
sample, and sets parameters through the nodes' parameter services. rclpy is imported when
one is made (``experiment --help`` stays cheap).
"""

from __future__ import annotations

import time
from typing import Any

from hexapod_vibration.contract import DRIVER_STATUS, NOTCH_STATUS, POINTING_STATUS

PACED_AHEAD_S = 1.5
"""How far (s) a paced monitor's sim time runs ahead of the driver's last report (reports
come once per simulated second): a stalled loop is not taken for a running one."""


class ExperimentError(RuntimeError):
    """The experiment could not run (a process died, the graph never came up, ...)."""


class GraphMonitor:
    """The runner's in-process rclpy node: watches /diagnostics, sets parameters."""

    def __init__(self, paced: bool = False) -> None:
        """Create the node on the caller's domain.

        ``sim_time_s`` follows the driver's ``sample`` on /diagnostics (once per simulated
        second); with ``paced`` (a realtime loop: one simulated second per wall second) it
        moves on with the wall clock from the last report, at most ``PACED_AHEAD_S`` past it.
        """
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.parameter_client import AsyncParameterClient
        from rclpy.signals import SignalHandlerOptions

        from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS

        self._rclpy = rclpy
        # No rclpy signal handlers: they would shut this context down from another thread
        # in the middle of a call (tracebacks); cli.StopSignal unwinds instead.
        rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("experiment")
        self._reported_s = -1.0              # the driver's last reported sample (s)
        self._reported_at = 0.0              # when it came (time.monotonic(), s)
        self._paced = paced
        self.driver: dict[str, str] = {}
        self.notch: dict[str, str] = {}
        self.pointing: dict[str, str] = {}
        self.recorder: dict[str, str] = {}
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag,
                                      DIAGNOSTICS_QOS)
        self.clients = {name: AsyncParameterClient(self.node, name)
                        for name in ("pph_driver", "notch_controller", "pointing_controller")}
        self._shaken: set[str] = set()       # clients whose services answered a handshake

    @property
    def sim_time_s(self) -> float:
        """The loop's sim time (s): the driver's last report (see ``__init__``)."""
        if self._paced and self._reported_s >= 0.0:
            ahead = min(time.monotonic() - self._reported_at, PACED_AHEAD_S)
            return self._reported_s + ahead
        return self._reported_s

    def _on_diag(self, msg: Any) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name == DRIVER_STATUS:
                self.driver = values
                reported = int(values.get("sample", 0)) / 1e3
                if reported > self._reported_s:
                    self._reported_s, self._reported_at = reported, time.monotonic()
            elif status.name == NOTCH_STATUS:
                self.notch = values
            elif status.name == POINTING_STATUS:
                self.pointing = values
            elif status.name.startswith("pph_recorder"):
                self.recorder = values

    def spin(self, seconds: float) -> None:
        """Process callbacks for ``seconds`` of wall time."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._rclpy.spin_once(self.node, timeout_sec=max(0.0, min(0.05, end -
                                                                      time.monotonic())))

    def _spin_once(self, timeout_s: float) -> None:
        self._rclpy.spin_once(self.node, timeout_sec=timeout_s)

    def graph_ready(self, with_notch: bool) -> bool:
        """Recorder, controllers and driver are all discovered on the loop topics."""
        n = self.node
        needed = [n.count_subscribers("/pph/accel") >= (2 if with_notch else 1),
                  n.count_subscribers("/pph/eddy") >= 2,
                  n.count_publishers("/pph/accel") >= 1,
                  n.count_publishers("/pph/pointing_command") >= 1]
        if with_notch:
            needed.append(n.count_publishers("/pph/notch_command") >= 1)
        return all(needed)

    def recorder_behind(self, topics: list[str], samples: int) -> list[str]:
        """Topics of which the recorder has not written sample ``samples - 1`` yet.

        Its last sample written (``<topic> last sample``): a reliable topic is delivered in
        order, so with its last sample every earlier one its publisher still held is
        written too (a realtime controller's skipped samples never come: a count of
        messages would wait for them).
        """
        return [t for t in topics
                if int(self.recorder.get(f"{t} last sample", "-1")) < samples - 1]

    def recorder_unmatched(self, topics: list[str]) -> list[str]:
        """Topics on which the recorder itself reports no matched publisher yet."""
        return [t for t in topics if int(self.recorder.get(f"{t} publishers", "0")) < 1]

    def writers_unmatched(self, topics: list[str]) -> list[str]:
        """Topics whose publisher has not matched every subscription the graph shows yet.

        The publishers' side (:mod:`hexapod_vibration.ros.matching`): a subscription that
        matched its publisher may not be matched by it yet, and loses what it sends.
        """
        from hexapod_vibration.ros.matching import unmatched_topics

        return unmatched_topics((self.driver, self.notch, self.pointing), topics,
                                self.node.count_subscribers)

    def set_parameter(self, node: str, name: str, value: Any, timeout_s: float = 10.0) -> None:
        """Set a parameter through the node's parameter service; raise if rejected."""
        from rclpy.parameter import Parameter

        from hexapod_vibration.ros.service_handshake import shake_hands

        client = self.clients[node]
        if not client.wait_for_services(timeout_sec=timeout_s):
            raise ExperimentError(f"/{node} parameter services not available")
        if node not in self._shaken:
            if silent := shake_hands(client, self._spin_once, timeout_s,
                                     services=("set_parameters",)):
                raise ExperimentError(f"/{node}: {', '.join(silent)} did not answer")
            self._shaken.add(node)
        future = client.set_parameters([Parameter(name, value=value)])
        self._rclpy.spin_until_future_complete(self.node, future, timeout_sec=timeout_s)
        if not future.done():
            raise ExperimentError(f"/{node}: no answer setting {name}")
        result = future.result().results[0]
        if not result.successful:
            raise ExperimentError(f"/{node} rejected {name}={value!r}: {result.reason}")

    def held_at(self, sample: int) -> bool:
        """True once the driver reported being held before ``sample``."""
        return self.driver.get("held") == "true" and int(self.driver.get("sample", -1)) == sample

    def close(self) -> None:
        """Destroy the node and shut rclpy down."""
        self.node.destroy_node()
        self._rclpy.try_shutdown()
