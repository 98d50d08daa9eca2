"""The whole loop on the numerical core alone (no ROS): plant, DC blocker, notch, pointing.

It runs a :class:`~hexapod_vibration.core.sim.scenario.Scenario` exactly as the ROS graph does
(same sample timing, same identification, same actuator limits), so the ROS experiment can
be compared sample for sample with it, and tests and benchmarks need no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.pointing import PointingController
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.plant import (
    PPHPlant,
    actuator_test_sine,
    rigid_body_mass_matrix,
    saturate_commands,
)
from hexapod_vibration.core.model.shaker import Shaker
from hexapod_vibration.core.sim.scenario import Scenario

STRUTS = 6
# Loop delay seen by the canceller's weights (samples): the command of sample n is first
# seen in the error of sample n+1, plus the anti-aliasing filter's group delay (~1 sample).
LOOP_DELAY_SAMPLES = 2.0


@dataclass
class LoopRecord:
    """Per-sample signals of a run (sample n = row n), SI units."""

    accel_m_s2: np.ndarray
    eddy_m: np.ndarray
    notch_command_n: np.ndarray
    pointing_command_n: np.ndarray
    actuator_force_n: np.ndarray
    relative_pose_true: np.ndarray
    top_accel_true: np.ndarray
    weights: np.ndarray
    control_on_sample: int
    plant_response: np.ndarray | None = None
    coefficients: np.ndarray | None = None
    mu_bound: float = float("nan")
    notes: list[str] = field(default_factory=list)


def strut_stiffness_n_per_m(config: ModelConfig) -> float:
    """Axial stiffness of a strut (suspension and joint contact in series), N/m."""
    st = config.strut
    return 1.0 / (1.0 / st.suspension_stiffness_n_per_m + 1.0 / st.joint_stiffness_n_per_m)


def make_pointing_controller(config: ModelConfig, sensing_matrix: np.ndarray,
                             sample_rate_hz: float) -> PointingController:
    """Pointing law tuned on the model's stiffness and payload mass matrix."""
    return PointingController(config.geometry, sensing_matrix, strut_stiffness_n_per_m(config),
                              rigid_body_mass_matrix(config.top_plate), sample_rate_hz)


def coefficients_for(plant_response: np.ndarray, mode: str, mu: float) -> tuple[np.ndarray, float]:
    """Adaptation coefficients for ``mode`` and the stability bound on ``mu`` (eq. 18).

    Raises ValueError when ``mu`` is at or beyond the bound of any tone.
    """
    coefficients = adaptation.normalized_coefficients(plant_response, mode)
    bound = min(adaptation.mu_bound(g, p, LOOP_DELAY_SAMPLES)
                for g, p in zip(plant_response, coefficients, strict=True))
    if mu >= bound:
        raise ValueError(f"mu={mu:g} is outside the stability bound {bound:.4g} ({mode})")
    return coefficients, bound


class CoreLoop:
    """Run a scenario on the core: the same steps the ROS nodes take each sample."""

    def __init__(self, config: ModelConfig, scenario: Scenario) -> None:
        """Build plant and controllers for ``scenario`` (model nonlinear or linear)."""
        self.scenario = scenario
        self.config = config if scenario.nonlinear else config.linear()
        fs = self.config.simulation.sample_rate_hz
        self.fs = fs
        rng = np.random.default_rng(scenario.seed)
        shaker = Shaker(scenario.shaker.tones(), scenario.shaker.noise_rms_n,
                        self.config.shaker.force_limit_n, seed=int(rng.integers(2**31)))
        self.plant = PPHPlant(self.config, shaker=shaker, seed=int(rng.integers(2**31)))
        self.pointing = make_pointing_controller(self.config, self.plant.eddy.sensing_matrix, fs)
        self.pointing.set_target(np.asarray(scenario.target_pose),
                                 self.config.strut.stroke_limit_m)
        self.dc_blocker = DCBlocker(STRUTS, fs)
        tones = scenario.notch.tone_frequencies_hz
        self.notch = AdaptiveNotchCanceller(STRUTS, tones, fs, scenario.notch.mu) if tones else None
        if self.notch is not None:
            self.notch.set_enabled(False, ramp_samples=0)
        self.identifier: adaptation.ToneResponseIdentifier | None = None

    def _notch_step(self, n: int, error: np.ndarray, record: LoopRecord) -> np.ndarray:
        sc = self.scenario
        if self.notch is None:
            return np.zeros(STRUTS)
        if n == int(round(sc.identify_at_s * self.fs)):
            self.identifier = adaptation.ToneResponseIdentifier(
                STRUTS, sc.notch.tone_frequencies_hz, self.fs)
        if self.identifier is not None:
            command = self.identifier.step(error)
            self.notch.step(error)                     # keeps its phase running
            if self.identifier.done:
                self._install_coefficients(record)
            return command
        if n == record.control_on_sample:
            self.notch.set_enabled(True)
        return self.notch.step(error)

    def _install_coefficients(self, record: LoopRecord) -> None:
        response = self.identifier.result()
        coefficients, bound = coefficients_for(response, self.scenario.notch.adaptation,
                                               self.scenario.notch.mu)
        self.notch.set_coefficients(coefficients)
        record.plant_response, record.coefficients, record.mu_bound = response, coefficients, bound
        self.identifier = None

    def run(self) -> LoopRecord:
        """Simulate the whole scenario and return every sample."""
        sc, n_samples = self.scenario, self.scenario.samples
        tones = len(sc.notch.tone_frequencies_hz)
        rec = LoopRecord(*(np.zeros((n_samples, STRUTS)) for _ in range(7)),
                         weights=np.zeros((n_samples, tones, STRUTS), complex),
                         control_on_sample=int(round(sc.control_on_s * self.fs)))
        sample = self.plant.step(np.zeros(STRUTS))
        sine = sc.test_sine
        for n in range(n_samples):
            notch = self._notch_step(n, self.dc_blocker.step(sample.accel_m_s2), rec)
            notch = notch + actuator_test_sine(n, sine.frequency_hz, sine.amplitude_n, self.fs)
            pointing = self.pointing.step(sample.eddy_m)
            applied = saturate_commands(notch, pointing, self.config.strut)
            rec.accel_m_s2[n], rec.eddy_m[n] = sample.accel_m_s2, sample.eddy_m
            rec.notch_command_n[n], rec.pointing_command_n[n] = notch, pointing
            rec.actuator_force_n[n] = applied
            rec.relative_pose_true[n] = sample.relative_pose_true
            rec.top_accel_true[n] = sample.top_accel_true
            if self.notch is not None:
                rec.weights[n] = self.notch.weights
            sample = self.plant.step(applied)
        return rec
