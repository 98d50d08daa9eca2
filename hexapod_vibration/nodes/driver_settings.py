"""The driver's parameters (``parameter_specs.PPH_DRIVER``) and what applying them changes.

:class:`DriverSettings` declares them (checked at start-up like a run-time change), keeps the
loop settings the driver reads every sample as plain attributes, builds the shaker and the
rotor from them, and applies run-time changes (post-set) to the
:class:`~hexapod_vibration.core.model.actuation.ActuatedPlant` it is bound to.
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node

from hexapod_vibration.core.model.actuation import ActuatedPlant
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.rotor import Rotor, rotor_or_none
from hexapod_vibration.core.model.shaker import Shaker, tones_from_arrays
from hexapod_vibration.parameter_specs import (
    NodeSpec,
    rotor_arrays,
    rotor_unpaired,
    shaker_tone_arrays,
    shaker_unpaired,
)
from hexapod_vibration.ros.parameters import NodeParameters

SHAKER_PARAMS = ("shaker_frequencies_hz", "shaker_amplitudes_n", "shaker_phases_rad",
                 "shaker_drift_hz", "shaker_drift_period_s", "shaker_noise_rms_n")
ROTOR_PARAMS = ("rotor_orders", "rotor_amplitudes_n", "rotor_reference_speed_hz",
                "rotor_profile_time_s", "rotor_profile_speed_hz")


class DriverSettings:
    """The driver's parameters: declared, read by the loop, applied to the plant."""

    def __init__(self, node: Node, spec: NodeSpec) -> None:
        """Declare ``spec``'s parameters on ``node`` and read the start-up values."""
        self._logger = node.get_logger()
        self.params = NodeParameters(node, spec)
        self._actuated: ActuatedPlant | None = None
        values = self.values()
        self.expected: list[str] = list(values["lockstep_controllers"])
        """The controllers lockstep waits for (read-only)."""
        self._set_loop_settings(values)
        self._warn(shaker_unpaired(values))
        self._warn(rotor_unpaired(values))

    def values(self) -> dict[str, Any]:
        """Every parameter's current value."""
        return self.params.values()

    def _set_loop_settings(self, values: dict[str, Any]) -> None:
        """The settings the loop reads every sample, as attributes (from ``values``)."""
        self.timeout_samples = int(values["command_timeout_samples"])
        """Watchdog: a stream older than this many samples gets zero force."""
        self.fade_samples = int(values["command_fade_samples"])
        """Watchdog: samples of the ramp to zero force (and back); 0 = a step."""
        self.lockstep_timeout_s = float(values["lockstep_timeout_s"])
        """Longest wait (s, wall) for the commands of one sample in lockstep."""
        self.hold_at_time_s = float(values["hold_at_time_s"])
        """Lockstep breakpoint (s of sim time), -1 = none."""
        self.tachometer = bool(values["rotor_tachometer"])
        """Publish the rotor's speed on /pph/reference_frequency."""

    def make_shaker(self, model: ModelConfig, seed: int) -> Shaker:
        """The shaker (with the rotor, if any) of the current values."""
        values = self.values()
        return Shaker(self._shaker_tones(values), values["shaker_noise_rms_n"],
                      model.shaker.force_limit_n, seed=seed + 1, rotor=self._rotor(values))

    def bind(self, actuated: ActuatedPlant) -> None:
        """Set the test sine on ``actuated`` and serve run-time changes (applied to it)."""
        self._actuated = actuated
        self._set_test_sine(self.values())
        self.params.serve(apply=self._apply)

    def _apply(self, changes: dict[str, Any]) -> None:
        """Apply validated run-time changes (post-set)."""
        values = self.values()
        self._set_loop_settings(values)
        self._set_test_sine(values)
        shaker = self._actuated.plant.shaker
        if any(name in changes for name in ROTOR_PARAMS):
            self._warn(rotor_unpaired(values))
            shaker.rotor = self._rotor(values)          # its phase restarts
        if any(name in changes for name in SHAKER_PARAMS):
            self._warn(shaker_unpaired(values))
            shaker.set_tones(self._shaker_tones(values))
            shaker.noise_rms_n = float(values["shaker_noise_rms_n"])

    def _set_test_sine(self, values: dict[str, Any]) -> None:
        sine = self._actuated.test_sine
        sine.frequency_hz = float(values["test_sine_frequency_hz"])
        sine.amplitude_n = float(values["test_sine_amplitude_n"])

    def _warn(self, unpaired: str) -> None:
        """Log what a pairing check of the arrays found (nothing if it found nothing)."""
        if unpaired:
            self._logger.warn(unpaired)

    @staticmethod
    def _rotor(values: dict[str, Any]) -> Rotor | None:
        """The rotor of the sounding ``rotor_*`` values (``parameter_specs.rotor_arrays``)."""
        orders, amplitudes, times, speeds = rotor_arrays(values)
        return rotor_or_none(orders, amplitudes, values["rotor_reference_speed_hz"], times,
                             speeds) if orders else None

    @staticmethod
    def _shaker_tones(values: dict[str, Any]) -> list:
        """The sounding tones (``parameter_specs.shaker_tone_arrays``) as ShakerTones."""
        return tones_from_arrays(*shaker_tone_arrays(values), values["shaker_drift_hz"],
                                 values["shaker_drift_period_s"])
