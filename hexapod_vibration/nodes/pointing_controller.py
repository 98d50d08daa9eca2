"""``pointing_controller``: the low-pass pointing law as a ROS 2 node.

Subscribes to ``/pph/eddy`` (six gap changes, m), recovers the top plate's pose relative
to the bottom plate, holds the commanded pose with integral action at a bandwidth of a few
Hz and publishes ``/pph/pointing_command`` (N, same sample index and run); its state and
the counts of refused ``/pph/eddy`` messages (malformed, beyond the gaps' physical range,
out of sequence) go to ``/diagnostics`` once per simulated second. The loop port
(:class:`~hexapod_vibration.ros.messages.ControllerLoopPort`) decides which samples to act
on; a new run of the driver (a restart) resets the law's integral and filters.
The set-point (tilt, twist, translation) and the loop's bandwidth are parameters, validated
against the platform's range (tilt within 2.5 deg, twist within 10 deg, stroke within 95 %).
"""

from __future__ import annotations

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import POINTING_STATUS, STRUT_COUNT
from hexapod_vibration.core.control.pointing import PointingGains, validate_target_pose
from hexapod_vibration.core.loop.signal_ranges import SignalRanges
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.sensors import EddySensorArray
from hexapod_vibration.core.sim.closed_loop import make_pointing_controller
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros import parameters as p
from hexapod_vibration.ros.diagnostics import diagnostic_array
from hexapod_vibration.ros.executors import declare_executor_parameter, run_node
from hexapod_vibration.ros.messages import (
    ControllerLoopPort,
    StrutArrayPublisher,
    create_loop_subscription,
)
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS, LOOP_PUBLISHER_QOS

TARGET_PARAMS = ("target_tilt_x_deg", "target_tilt_y_deg", "target_twist_deg",
                 "target_translation_m")
GAIN_PARAMS = ("bandwidth_hz", "damping_ratio", "output_lowpass_hz")
DIAGNOSTICS_EVERY_SAMPLES = 1000


class PointingControllerNode(Node):
    """Pointing law node: eddy gaps in, strut forces out."""

    def __init__(self) -> None:
        """Declare parameters, build the law from the model, wire the topics."""
        super().__init__("pointing_controller")
        self._declare_parameters()
        model = load_model_config(self.get_parameter("model_file").value or
                                  config_path("pph_model.yaml"))
        self.model = model
        height = float(model.geometry.top_joints_m[0, 2])
        sensing = EddySensorArray(model.eddy, height).sensing_matrix
        self.law = make_pointing_controller(model, sensing, model.simulation.sample_rate_hz)
        self.law.set_gains(self._gains({}))
        self.law.set_target(self._target({}), model.strut.stroke_limit_m)
        self.enabled = bool(self.get_parameter("enabled").value)
        self.port = ControllerLoopPort(
            "/pph/eddy", SignalRanges.from_model(model).eddy_m,
            StrutArrayPublisher(self.create_publisher(
                Float64MultiArray, "/pph/pointing_command", LOOP_PUBLISHER_QOS)),
            self.get_logger())
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.loop_subscriptions = [create_loop_subscription(self, "/pph/eddy", self._on_eddy)]
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(f"pointing controller up: target {np.round(self.law.target, 6)}"
                               f", bandwidth {self.law.gains.bandwidth_hz} Hz")

    def _declare_parameters(self) -> None:
        p.declare_float(self, "target_tilt_x_deg", 0.0, "commanded tilt about x (deg)",
                        -2.5, 2.5)
        p.declare_float(self, "target_tilt_y_deg", 0.0, "commanded tilt about y (deg)",
                        -2.5, 2.5)
        p.declare_float(self, "target_twist_deg", 0.0, "commanded twist about z (deg)",
                        -10.0, 10.0)
        p.declare_float_array(self, "target_translation_m", [0.0, 0.0, 0.0], "commanded "
                              "translation x, y, z of the payload (m)", -1e-3, 1e-3)
        p.declare_float(self, "bandwidth_hz", 1.5, "pointing bandwidth: the integral pole "
                        "(Hz), far below the vibration tones", 0.05, 5.0)
        p.declare_float(self, "damping_ratio", 0.7, "damping given to the suspension modes",
                        0.05, 2.0)
        p.declare_float(self, "output_lowpass_hz", 15.0, "2nd-order low-pass on the forces "
                        "(Hz)", 2.0, 100.0)
        p.declare_bool(self, "enabled", True, "pointing forces on (off: zero force, integral "
                       "reset)")
        p.declare_string(self, "model_file", "", "physical model YAML (empty: packaged "
                         "config/pph_model.yaml)", read_only=True)
        declare_executor_parameter(self)

    def _value(self, changes: dict, name: str):
        return changes[name] if name in changes else self.get_parameter(name).value

    def _target(self, changes: dict) -> np.ndarray:
        translation = list(self._value(changes, "target_translation_m") or [])
        if len(translation) != 3:
            raise ValueError(f"target_translation_m needs 3 values (m), got {len(translation)}")
        angles = np.deg2rad([self._value(changes, n) for n in TARGET_PARAMS[:3]])
        return np.concatenate([translation, angles])

    def _gains(self, changes: dict) -> PointingGains:
        return PointingGains(*(float(self._value(changes, n)) for n in GAIN_PARAMS),
                             force_limit_n=self.model.strut.force_limit_static_n)

    def _on_set_parameters(self, params: list[Parameter]):
        changes = {q.name: q.value for q in params}
        try:
            target = self._target(changes)
            validate_target_pose(target, self.law.geometry, self.model.strut.stroke_limit_m)
            gains = self._gains(changes)
        except ValueError as exc:
            return p.reject(str(exc))
        if any(n in changes for n in TARGET_PARAMS):
            self.law.set_target(target, self.model.strut.stroke_limit_m)
        if any(n in changes for n in GAIN_PARAMS):
            self.law.set_gains(gains)
        if "enabled" in changes and bool(changes["enabled"]) != self.enabled:
            self.enabled = bool(changes["enabled"])
            self.law.reset()
        return p.accept()

    def _on_eddy(self, msg: Float64MultiArray | bytes) -> None:
        sample = self.port.receive(msg)
        if sample is None:
            return
        if sample.new_run:
            self.law.reset()
        force = self.law.step(sample.values) if self.enabled else np.zeros(STRUT_COUNT)
        self.port.answer(force, sample)
        if sample.index % DIAGNOSTICS_EVERY_SAMPLES == 0:
            self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """State and the counts of refused /pph/eddy messages on /diagnostics."""
        counters = self.port.diagnostics()
        values = {"enabled": str(self.enabled).lower(), "last_sample": self.port.last_sample,
                  "run": self.port.sequence.run, **counters,
                  "target_pose_m_rad": np.round(self.law.target, 9).tolist()}
        message = "enabled" if self.enabled else "disabled"
        self._pub_diag.publish(diagnostic_array(POINTING_STATUS, bool(counters["invalid"]),
                                                message, values, self.port.last_sample))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration pointing_controller``."""
    run_node("pointing_controller", PointingControllerNode, args=args)


if __name__ == "__main__":
    main()
