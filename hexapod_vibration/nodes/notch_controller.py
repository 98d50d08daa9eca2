"""``notch_controller``: six decentralized Adaptive Notch Cancellers (the paper's algorithm).

Subscribes to ``/pph/accel`` (raw, gravity included), removes the DC with a DC blocker,
runs the canceller for every strut and tone, and publishes ``/pph/notch_command`` with the
same sample index. Before adapting it identifies the plant at its tones (a few seconds of
test tones, one strut at a time, while the shaker keeps running) and derives the
adaptation coefficients, so that ``mu`` is a normalised convergence rate (1/sample) whose
stability bound is known; values beyond the bound are rejected with the reason.
Weights are published at 100 Hz on ``/pph/notch_weights``; status on ``/diagnostics``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from hexapod_vibration.contract import sample_label
from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller, validate_frequencies
from hexapod_vibration.ros import parameters as p
from hexapod_vibration.ros.diagnostics import diagnostic_array
from hexapod_vibration.ros.executors import declare_executor_parameter, run_node
from hexapod_vibration.ros.messages import StrutArrayPublisher, receive_strut_array
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS, LOOP_PUBLISHER_QOS, LOOP_QOS

STRUTS = 6
SAMPLE_RATE_HZ = 1000.0
MAX_TONES = 16
WEIGHTS_EVERY_SAMPLES = 10


def _tone_key(frequency_hz: float) -> float:
    return round(float(frequency_hz), 6)


@dataclass(frozen=True)
class _Plan:
    """A checked set of parameter changes: resulting tones, mode, response, P and bound."""

    tones: list[float]
    mode: str
    response: np.ndarray | None
    coefficients: np.ndarray | None
    bound: float


class NotchControllerNode(Node):
    """Adaptive Notch Canceller node: parameters in, commands out, nothing numerical here."""

    def __init__(self) -> None:
        """Declare parameters, build the canceller, wire topics and the identify service."""
        super().__init__("notch_controller")
        self._declare_parameters()
        self.fs = SAMPLE_RATE_HZ
        self.delay = self.get_parameter("loop_delay_samples").value
        tones = p.parameter_value(self, "tone_frequencies_hz") or []
        raw = self.get_parameter("adaptation").value == "raw"
        # Raw (paper as printed, P = I) adapts at once; the normalised modes wait for the
        # identification to give them their coefficients.
        self.canceller = AdaptiveNotchCanceller(STRUTS, tones if raw else [], self.fs,
                                                self.get_parameter("mu").value)
        if not raw:
            self.canceller.set_tone_frequencies(tones, ramp_samples=0)
        self.canceller.set_enabled(False, ramp_samples=0)
        self._identify_delay = int(round(self.get_parameter("identify_delay_s").value * self.fs))
        self._auto_identify = bool(self.get_parameter("auto_identify").value)
        self._command = np.zeros(STRUTS)      # the canceller writes each sample here
        self.dc_blocker = DCBlocker(STRUTS, self.fs, self.get_parameter("dc_cutoff_hz").value)
        self.identifier: adaptation.ToneResponseIdentifier | None = None
        self.plant_response: np.ndarray | None = None
        self.identified_tones: list[float] = []
        self._responses: dict[float, np.ndarray] = {}    # tone (Hz) -> identified G (6, 6)
        self.bound = self._normalised_bound()
        self.last_sample = -1
        self.first_sample = -1
        self.enabled_since_sample = -1
        self.counters = {"invalid": 0, "gaps": 0, "missed_samples": 0, "duplicates": 0}
        pub_qos = LOOP_PUBLISHER_QOS
        self._pub_cmd = StrutArrayPublisher(self.create_publisher(
            Float64MultiArray, "/pph/notch_command", pub_qos))
        self._pub_w = self.create_publisher(Float64MultiArray, "/pph/notch_weights", pub_qos)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.loop_subscriptions = [self.create_subscription(
            Float64MultiArray, "/pph/accel", self._on_accel, LOOP_QOS)]
        self.create_service(Trigger, "~/identify", self._on_identify)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._want_enabled = bool(self.get_parameter("enabled").value)
        self.bound = self._plan({"mu": self.canceller.mu, "tone_frequencies_hz": tones,
                                 "adaptation": self.get_parameter("adaptation").value}).bound
        if raw or not self._auto_identify:
            self.canceller.set_enabled(self._want_enabled, ramp_samples=0)
        self.get_logger().info(f"notch controller up: tones {tones} Hz, mu "
                               f"{self.canceller.mu:g}, {self.get_parameter('adaptation').value}")

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        p.declare_float(self, "mu", 0.002, "normalised adaptation rate (1/sample): the "
                        "weights converge as (1 - mu)^n; bounded by the identified stability "
                        "limit (eq. 18 with the loop delay)", 0.0, 1.0)
        p.declare_float_array(self, "tone_frequencies_hz", [40.0, 80.0],
                              "tones to cancel (Hz), each in (0, 500), at most 16", 0.0,
                              SAMPLE_RATE_HZ / 2)
        p.declare_bool(self, "enabled", True, "control output on (ramped, bumpless); while "
                       "off the weights are frozen and kept")
        p.declare_string(self, "adaptation", "decentralized", "adaptation coefficient: "
                         "decentralized = six SISO loops, each normalised by its own strut's "
                         "identified gain and phase (the paper); centralized = -2 G^-1 (6x6); "
                         "raw = the paper as printed (P = I, mu unnormalised)",
                         adaptation.COEFFICIENT_MODES)
        p.declare_bool(self, "auto_identify", True, "identify the plant at start-up and "
                       "whenever the tones change")
        p.declare_float(self, "identify_delay_s", 1.0, "wait after the first sample before "
                        "the start-up identification (s of samples)", 0.0, 60.0)
        p.declare_float(self, "identification_amplitude_n", 2.0, "test-tone amplitude per "
                        "tone during identification (N peak)", 0.01, 20.0)
        p.declare_float(self, "identification_settle_s", 0.1, "discarded settling time per "
                        "identification segment (s)", 0.0, 5.0, read_only=True)
        p.declare_float(self, "identification_measure_s", 0.3, "fitted time per "
                        "identification segment (s)", 0.05, 10.0, read_only=True)
        p.declare_float(self, "dc_cutoff_hz", 0.5, "DC-blocker corner (Hz)", 0.01, 10.0,
                        read_only=True)
        p.declare_float(self, "loop_delay_samples", 2.0, "loop delay used in the stability "
                        "bound (samples): 1 for the ZOH + anti-aliasing group delay", 0.0, 20.0,
                        read_only=True)
        p.declare_float(self, "ramp_s", 0.05, "enable/disable fade time (s)", 0.0, 5.0)
        declare_executor_parameter(self)

    def _on_set_parameters(self, params: list[Parameter]):
        changes = {q.name: q.value for q in params}
        try:
            plan = self._plan(changes)
        except ValueError as exc:
            return p.reject(str(exc))
        self._apply(changes, plan)
        return p.accept()

    def _check_tones(self, changes: dict) -> str:
        if "tone_frequencies_hz" not in changes:
            return ""
        tones = list(changes["tone_frequencies_hz"] or [])
        if len(tones) > MAX_TONES:
            return f"at most {MAX_TONES} tones, got {len(tones)}"
        try:
            validate_frequencies(tones, self.fs)
        except ValueError as exc:
            return f"tone_frequencies_hz rejected: {exc}"
        return ""

    def _plan(self, changes: dict) -> _Plan:
        """Check a set of parameter changes as a whole, changing nothing.

        The stability bound is that of the resulting mode and tone set (the identified
        plant at those tones, else the normalised bound), so a change of ``adaptation`` or
        of the tones is rejected too if it would leave the present ``mu`` unstable.

        Raises:
            ValueError: the reason to reject the changes.
        """
        reason = self._check_tones(changes)
        if reason:
            raise ValueError(reason)
        if "tone_frequencies_hz" in changes:
            tones = [float(f) for f in changes["tone_frequencies_hz"] or []]
        else:
            tones = [float(f) for f in self.canceller.tone_frequencies_hz]
        mode = changes.get("adaptation", self.get_parameter("adaptation").value)
        if mode not in adaptation.COEFFICIENT_MODES:
            raise ValueError(f"adaptation must be one of {adaptation.COEFFICIENT_MODES}, "
                             f"got {mode!r}")
        if "tone_frequencies_hz" in changes or "adaptation" in changes:
            response = self._known_response(tones)
            try:
                coefficients, bound = self._coefficients_for(tones, response, mode)
            except ValueError as exc:
                raise ValueError(f"adaptation={mode!r} rejected: {exc}") from None
        else:
            response, coefficients, bound = self.plant_response, None, self.bound
        mu = changes.get("mu", self.canceller.mu)
        if not np.isfinite(mu) or mu < 0.0:
            raise ValueError(f"mu must be finite and >= 0, got {mu}")
        if mu >= bound and any(k in changes for k in ("mu", "adaptation",
                                                      "tone_frequencies_hz")):
            raise ValueError(f"mu={mu:g} is outside the stability bound {bound:.4g} ({mode} "
                             f"adaptation at {tones} Hz, eq. 18 with a {self.delay:g}-sample "
                             "loop delay)")
        return _Plan(tones, mode, response, coefficients, bound)

    def _apply(self, changes: dict, plan: _Plan) -> None:
        if "mu" in changes:
            self.canceller.set_mu(changes["mu"])
        tones_changed = "tone_frequencies_hz" in changes
        mode_changed = "adaptation" in changes
        if tones_changed:
            self.canceller.set_tone_frequencies(plan.tones, coefficients=plan.coefficients,
                                                ramp_samples=self.ramp_samples)
        elif mode_changed and plan.coefficients is not None:
            self.canceller.set_coefficients(plan.coefficients)
        self.plant_response, self.bound = plan.response, plan.bound
        self.identified_tones = plan.tones if plan.response is not None else []
        if "enabled" in changes:
            self._set_enabled(bool(changes["enabled"]))
        if "ramp_s" in changes:
            self._ramp_samples = int(round(changes["ramp_s"] * self.fs))
        if "identify_delay_s" in changes:
            self._identify_delay = int(round(changes["identify_delay_s"] * self.fs))
        if "auto_identify" in changes:
            self._auto_identify = bool(changes["auto_identify"])
        if tones_changed or mode_changed:
            self._after_tone_or_mode_change(plan, mode_changed)

    def _after_tone_or_mode_change(self, plan: _Plan, mode_changed: bool) -> None:
        """Identify what the new tone set or mode needs; drop an identification it does not."""
        if plan.response is not None or plan.mode == "raw" or not plan.tones:
            if self.identifier is not None:    # nothing to measure any more: bumpless stop
                self.get_logger().info("identification no longer needed: stopped")
                self.identifier = None
                self.canceller.set_frozen(False)
                self.canceller.set_enabled(self._want_enabled, self.ramp_samples)
            return
        if mode_changed:      # a normalised mode must not adapt with another mode's P
            self.canceller.set_frozen(True)
        running = self.identifier is not None and np.array_equal(
            self.identifier.tone_frequencies_hz, plan.tones)
        if self._auto_identify and self.first_sample >= 0 and not running:
            self.start_identification(plan.tones)

    @property
    def ramp_samples(self) -> int:
        """Fade length (samples) for enable/disable and removed tones."""
        return getattr(self, "_ramp_samples", int(round(self.get_parameter("ramp_s").value
                                                        * self.fs)))

    def _set_enabled(self, flag: bool) -> None:
        self._want_enabled = flag
        if self.identifier is None:
            self.canceller.set_enabled(flag, self.ramp_samples)
        self.enabled_since_sample = self.last_sample + 1 if flag else -1
        self.publish_diagnostics()

    # ------------------------------------------------------------------ identification
    def _normalised_bound(self) -> float:
        return adaptation.delayed_mode_mu_bound(1.0, self.delay)

    def _known_response(self, tones: list[float]) -> np.ndarray | None:
        """Identified G (T, 6, 6) at ``tones``, or None if a tone was never identified."""
        rows = [self._responses.get(_tone_key(f)) for f in tones]
        if not rows or any(r is None for r in rows):
            return None
        return np.stack(rows)

    def _coefficients_for(self, tones: list[float], response: np.ndarray | None,
                          mode: str) -> tuple[np.ndarray | None, float]:
        """Coefficients for the canceller (None: new tones wait) and the mu bound."""
        if response is not None:
            return self._coefficients(response, mode)
        if mode == "raw":
            identity = np.broadcast_to(np.eye(STRUTS, dtype=complex), (len(tones), STRUTS, STRUTS))
            return (identity.copy() if tones else None), np.inf
        return None, self._normalised_bound()

    def _coefficients(self, response: np.ndarray, mode: str) -> tuple[np.ndarray, float]:
        coefficients = adaptation.normalized_coefficients(response, mode)
        bound = min(adaptation.mu_bound(g, c, self.delay)
                    for g, c in zip(response, coefficients, strict=True))
        return coefficients, bound

    def start_identification(self, tones: list[float] | None = None) -> None:
        """Begin measuring G at the tones; the canceller is frozen meanwhile."""
        tones = [float(f) for f in (tones if tones is not None
                                    else self.canceller.tone_frequencies_hz)]
        if not tones:
            return
        self.identifier = adaptation.ToneResponseIdentifier(
            STRUTS, tones, self.fs, self.get_parameter("identification_amplitude_n").value,
            self.get_parameter("identification_settle_s").value,
            self.get_parameter("identification_measure_s").value)
        self.canceller.set_frozen(True)
        self.get_logger().info(f"identifying the plant at {tones} Hz "
                               f"({self.identifier.duration_s:.1f} s of samples)")

    def _finish_identification(self) -> None:
        response = self.identifier.result()
        for f, g in zip(self.identifier.tone_frequencies_hz, response, strict=True):
            self._responses[_tone_key(f)] = g
        self.identifier = None
        self.canceller.set_frozen(False)
        tones = [float(f) for f in self.canceller.tone_frequencies_hz]
        mode = self.get_parameter("adaptation").value
        current = self._known_response(tones)
        try:
            if current is None:
                raise ValueError(f"no identified response at {tones} Hz")
            coefficients, bound = self._coefficients(current, mode)
        except ValueError as exc:
            self.canceller.set_frozen(True)
            self.get_logger().error(f"identification unusable for {mode}: {exc}; not adapting")
            return
        self.plant_response, self.identified_tones, self.bound = current, tones, bound
        self.canceller.set_coefficients(coefficients)
        self._clamp_mu(bound)
        self.canceller.set_enabled(self._want_enabled, self.ramp_samples)
        if self._want_enabled and self.enabled_since_sample < 0:
            self.enabled_since_sample = self.last_sample + 1
        gains = np.abs(np.diagonal(current, axis1=1, axis2=2)).mean(axis=1)
        self.get_logger().info(f"identified: |G_ii| {np.round(gains, 4)} (m/s^2)/N, mu bound "
                               f"{bound:.4g}")
        self.publish_diagnostics()

    def _clamp_mu(self, bound: float) -> None:
        mu = self.canceller.mu
        if mu < bound:
            return
        clamped = 0.5 * bound
        self.get_logger().warn(f"mu={mu:g} is outside the identified stability bound "
                               f"{bound:.4g}: clamped to {clamped:.4g}")
        self.set_parameters([Parameter("mu", value=clamped)])

    def _on_identify(self, _request, response):
        if not len(self.canceller.tone_frequencies_hz):
            response.success, response.message = False, "no tones to identify"
            return response
        self.start_identification()
        response.success = True
        response.message = f"identifying for {self.identifier.duration_s:.1f} s of samples"
        return response

    # ------------------------------------------------------------------ loop
    def _on_accel(self, msg: Float64MultiArray | bytes) -> None:
        parsed = receive_strut_array(msg, self.get_logger(), "/pph/accel")
        if parsed is None:
            self.counters["invalid"] += 1
            return
        accel, index = parsed
        index = self.last_sample + 1 if index is None else index
        if index <= self.last_sample:
            self.counters["duplicates"] += 1
            return
        self._catch_up(index)
        command = self._step(self.dc_blocker.step(accel))
        self._pub_cmd.publish(command, index)
        if index % WEIGHTS_EVERY_SAMPLES == 0:
            self._publish_weights(index)
        if index % int(self.fs) == 0:
            self.publish_diagnostics()

    def _catch_up(self, index: int) -> None:
        """Keep the phase references on the sample grid across missing samples."""
        if self.first_sample < 0:
            self.first_sample = index
        elif index > self.last_sample + 1:
            gap = index - self.last_sample - 1
            self.counters["gaps"] += 1
            self.counters["missed_samples"] += gap
            self.canceller.advance(gap)
            self.get_logger().warn(f"/pph/accel: {gap} samples missing before {index}")
            if self.identifier is not None:
                self.get_logger().warn("samples missed during identification: restarting it")
                self.start_identification(list(self.identifier.tone_frequencies_hz))
        self.last_sample = index
        if (index - self.first_sample == self._identify_delay and self.plant_response is None
                and self.identifier is None and self._auto_identify):
            self.start_identification()

    def _step(self, error: np.ndarray) -> np.ndarray:
        command = self.canceller.step(error, out=self._command)
        if self.identifier is not None:
            command = command + self.identifier.step(error)
            if self.identifier.done:
                self._finish_identification()
        return command

    def _publish_weights(self, index: int) -> None:
        w = self.canceller.weights
        tones = w.shape[0]
        msg = Float64MultiArray()
        msg.layout.dim = [MultiArrayDimension(label="tone", size=tones, stride=tones * 12),
                          MultiArrayDimension(label="strut", size=6, stride=12),
                          MultiArrayDimension(label="a_b", size=2, stride=2),
                          MultiArrayDimension(label=sample_label(index), size=1, stride=1)]
        msg.data = np.stack([w.real, -w.imag], axis=-1).ravel().tolist()
        self._pub_w.publish(msg)

    def publish_diagnostics(self) -> None:
        """Controller state on /diagnostics (also on every enable/identify change)."""
        state = ("identifying" if self.identifier is not None else
                 "adapting" if self.canceller.enabled and self.plant_response is not None
                 else "enabled" if self.canceller.enabled else "disabled")
        values = {"state": state, "enabled": self._want_enabled,
                  "enabled_since_sample": self.enabled_since_sample,
                  "last_sample": self.last_sample, "mu": self.canceller.mu,
                  "mu_bound": self.bound, "adaptation": self.get_parameter("adaptation").value,
                  "tones_hz": [float(f) for f in self.canceller.tone_frequencies_hz],
                  "identified_tones_hz": self.identified_tones, **self.counters}
        if self.plant_response is not None:
            diag = np.diagonal(self.plant_response, axis1=1, axis2=2)
            values["plant_gain_m_s2_per_n"] = np.round(np.abs(diag).mean(axis=1), 6).tolist()
            values["plant_phase_deg"] = np.round(np.rad2deg(np.angle(diag.mean(axis=1))),
                                                 2).tolist()
        self._pub_diag.publish(diagnostic_array("notch_controller",
                                                bool(self.counters["invalid"]), state, values,
                                                self.last_sample))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration notch_controller``."""
    run_node("notch_controller", NotchControllerNode, args=args)


if __name__ == "__main__":
    main()
