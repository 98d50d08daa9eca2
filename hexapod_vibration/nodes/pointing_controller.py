"""``pointing_controller``: the low-pass pointing law as a ROS 2 node.

Subscribes to ``/pph/eddy`` (six gap changes, m), recovers the top plate's pose relative
to the bottom plate, holds the commanded pose with integral action at a bandwidth of a few
Hz and publishes ``/pph/pointing_command`` (N, same sample index and run); its state and
the counts of refused ``/pph/eddy`` messages (malformed, beyond the gaps' physical range,
out of sequence) go to ``/diagnostics`` once per simulated second. The loop port
(:class:`~hexapod_vibration.ros.messages.ControllerLoopPort`) decides which samples to act
on; a new run of the driver (a restart) resets the law's integral and filters. Behind (a
realtime stall), the node answers only the newest samples, but the law steps through every
sample since its last one: those skipped as they were received, those lost as the
continuation of the eddy signal (:mod:`~hexapod_vibration.core.control.gap_bridge`, counted
as ``lost_samples_stood_in``), so its rate and low-pass cross the gap without a kick.
The set-point (tilt, twist, translation) and the loop's bandwidth are parameters, validated
against the platform's range (tilt within 2.5 deg, twist within 10 deg, stroke within 95 %).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    DIAGNOSTICS_EVERY_SAMPLES,
    DIAGNOSTICS_PHASE_SAMPLES,
    FORECAST_PHASE_SAMPLES,
    POINTING_FORECAST_TOPIC,
    POINTING_STATUS,
    STRUT_COUNT,
)
from hexapod_vibration.core.control.gap_bridge import GapBridge
from hexapod_vibration.core.control.pointing import PointingGains, validate_target_pose
from hexapod_vibration.core.control.tone_continuation import ToneContinuation
from hexapod_vibration.core.loop.command_arbiter import NO_FORCE_N  # zero force, read-only
from hexapod_vibration.core.loop.idle_work import IdleWork
from hexapod_vibration.core.loop.signal_ranges import SignalRanges
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.sensors import EddySensorArray
from hexapod_vibration.core.sim.closed_loop import make_pointing_controller
from hexapod_vibration.parameter_specs import POINTING_CONTROLLER
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.command_forecasts import ForecastPublisher
from hexapod_vibration.ros.diagnostics import diagnostic_array, publish_status_periodically
from hexapod_vibration.ros.executors import loop_meter
from hexapod_vibration.ros.matching import MatchedReaders
from hexapod_vibration.ros.messages import (
    ControllerLoopPort,
    StrutArrayPublisher,
    create_loop_subscription,
)
from hexapod_vibration.ros.node_runner import run_node
from hexapod_vibration.ros.parameters import NodeParameters
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS, LOOP_PUBLISHER_QOS

TARGET_PARAMS = ("target_tilt_x_deg", "target_tilt_y_deg", "target_twist_deg",
                 "target_translation_m")
GAIN_PARAMS = ("bandwidth_hz", "damping_ratio", "output_lowpass_hz")
DIAGNOSTICS_PHASE = DIAGNOSTICS_PHASE_SAMPLES["pointing_controller"]


class PointingControllerNode(Node):
    """Pointing law node: eddy gaps in, strut forces out."""

    def __init__(self) -> None:
        """Declare parameters, build the law from the model, wire the topics."""
        super().__init__("pointing_controller")
        self.params = NodeParameters(self, POINTING_CONTROLLER)
        values = self.params.values()
        model = load_model_config(values["model_file"] or config_path("pph_model.yaml"))
        self.model = model
        height = float(model.geometry.top_joints_m[0, 2])
        sensing = EddySensorArray(model.eddy, height).sensing_matrix
        self.law = make_pointing_controller(model, sensing, model.simulation.sample_rate_hz)
        self.params.serve(check=self._check_parameters, apply=self._apply_parameters)
        self.law.set_gains(self._gains(values))
        self.law.set_target(self._target(values), model.strut.stroke_limit_m)
        self.enabled = bool(values["enabled"])
        self.readers = MatchedReaders(self.publish_diagnostics)
        self.port = ControllerLoopPort(
            "/pph/eddy", SignalRanges.from_model(model).eddy_m,
            StrutArrayPublisher(self.readers.publisher(
                self, Float64MultiArray, "/pph/pointing_command", LOOP_PUBLISHER_QOS)),
            self.get_logger())
        self._continuation = ToneContinuation(STRUT_COUNT)
        self.idle_work = IdleWork()                   # run by the loop's spinner when idle
        self._forecasts = ForecastPublisher(            # for late samples
            self, POINTING_FORECAST_TOPIC, FORECAST_PHASE_SAMPLES["pointing_controller"],
            self._continuation.forecast, self.idle_work, self.port.last_acted)
        self._bridge = GapBridge(STRUT_COUNT)         # the law's input across skipped samples
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        publish_status_periodically(self, self.publish_diagnostics)
        self.loop_subscriptions = [create_loop_subscription(self, "/pph/eddy", self._on_eddy)]
        # Stale samples are skipped (not answered) but the law steps through them.
        self.latest_only_subscriptions = self.loop_subscriptions
        self.skipped_message_callbacks = {self.loop_subscriptions[0]: self.port.hold_skipped}
        self.meter = loop_meter()
        self._count = self.meter.counter("pointing_controller")
        self._stage = {name: self.meter.stage(f"pointing {name}")
                       for name in ("decode", "law", "publish", "report")}
        self.get_logger().info(f"pointing controller up: target {np.round(self.law.target, 6)}"
                               f", bandwidth {self.law.gains.bandwidth_hz} Hz")

    @staticmethod
    def _target(values: Mapping) -> np.ndarray:
        """Commanded pose [x, y, z (m), rx, ry, rz (rad)] from the parameter values."""
        angles = np.deg2rad([values[n] for n in TARGET_PARAMS[:3]])
        return np.concatenate([values["target_translation_m"], angles])

    def _gains(self, values: Mapping) -> PointingGains:
        return PointingGains(*(float(values[n]) for n in GAIN_PARAMS),
                             force_limit_n=self.model.strut.force_limit_static_n)

    def _check_parameters(self, values: Mapping, changed: frozenset) -> str:
        """The pose within the platform's range (core check), the gains realisable."""
        try:
            if changed & set(TARGET_PARAMS):
                validate_target_pose(self._target(values), self.law.geometry,
                                     self.model.strut.stroke_limit_m)
            if changed & set(GAIN_PARAMS):
                self._gains(values)
        except ValueError as exc:
            return str(exc)
        return ""

    def _apply_parameters(self, changes: dict) -> None:
        values = self.params.values()
        if any(n in changes for n in TARGET_PARAMS):
            self.law.set_target(self._target(values), self.model.strut.stroke_limit_m)
        if any(n in changes for n in GAIN_PARAMS):
            self.law.set_gains(self._gains(values))
        if "enabled" in changes and bool(changes["enabled"]) != self.enabled:
            self.enabled = bool(changes["enabled"])
            self.law.reset()

    def _on_eddy(self, msg: Float64MultiArray | bytes) -> None:
        meter, stage = self.meter, self._stage
        sample = self.port.receive(msg)
        meter.lap(stage["decode"])
        if sample is None:
            return
        if sample.new_run:
            self.law.reset()
            self._bridge.reset()
        force = NO_FORCE_N
        for gaps in self._bridge.inputs(sample.index, sample.values, sample.skipped):
            if self.enabled:             # every sample since the last: the law's state
                force = self.law.step(gaps)
            self._continuation.add(force)
        meter.lap(stage["law"])
        self.port.answer(force, sample)
        self._forecasts.after(sample.index)
        meter.lap(stage["publish"])
        self._count()
        if sample.index % DIAGNOSTICS_EVERY_SAMPLES == DIAGNOSTICS_PHASE:
            self.publish_diagnostics()
            meter.lap(stage["report"])

    def publish_diagnostics(self) -> None:
        """State and the counts of refused /pph/eddy messages on /diagnostics."""
        counters = self.port.diagnostics()
        values = {"enabled": str(self.enabled).lower(), "last_sample": self.port.last_sample,
                  "run": self.port.sequence.run, **counters, **self.readers.values(),
                  "target_pose_m_rad": np.round(self.law.target, 9).tolist(),
                  "lost_samples_stood_in": self._bridge.stood_in, "law_kernels": self.law.kernels,
                  **self.meter.report()}
        message = "enabled" if self.enabled else "disabled"
        self._pub_diag.publish(diagnostic_array(POINTING_STATUS, bool(counters["invalid"]),
                                                message, values, self.port.last_sample))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration pointing_controller``."""
    run_node("pointing_controller", PointingControllerNode, args=args)


if __name__ == "__main__":
    main()
