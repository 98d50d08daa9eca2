"""The whole loop on the numerical core alone (no ROS): plant, notch supervisor, pointing.

It runs a :class:`~hexapod_vibration.core.sim.scenario.Scenario` exactly as the ROS graph does:
the same :class:`~hexapod_vibration.core.control.notch_supervisor.NotchSupervisor` as the
``notch_controller`` node, given the settings the experiment runner gives the node
(:func:`notch_config`), the same sample timing and actuator limits. So the ROS experiment
can be compared sample for sample with it, and tests, benchmarks and sweeps need no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hexapod_vibration.contract import STRUT_COUNT
from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor
from hexapod_vibration.core.control.pointing import PointingController
from hexapod_vibration.core.model.actuation import ActuatedPlant
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.plant import PPHPlant, rigid_body_mass_matrix
from hexapod_vibration.core.model.shaker import Shaker
from hexapod_vibration.core.sim.scenario import Scenario, notch_config

STRUTS = STRUT_COUNT


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
    tone_estimates_hz: np.ndarray | None = None


def strut_stiffness_n_per_m(config: ModelConfig) -> float:
    """Axial stiffness of a strut (suspension and joint contact in series), N/m."""
    st = config.strut
    return 1.0 / (1.0 / st.suspension_stiffness_n_per_m + 1.0 / st.joint_stiffness_n_per_m)


def make_pointing_controller(config: ModelConfig, sensing_matrix: np.ndarray,
                             sample_rate_hz: float) -> PointingController:
    """Pointing law tuned on the model's stiffness and payload mass matrix."""
    return PointingController(config.geometry, sensing_matrix, strut_stiffness_n_per_m(config),
                              rigid_body_mass_matrix(config.top_plate), sample_rate_hz)


class CoreLoop:
    """Run a scenario on the core: the same steps the ROS nodes take each sample."""

    def __init__(self, config: ModelConfig, scenario: Scenario) -> None:
        """Build plant and controllers for ``scenario`` (model nonlinear or linear)."""
        self.scenario = scenario
        self.config = config if scenario.nonlinear else config.linear()
        fs = self.config.simulation.sample_rate_hz
        self.fs = fs
        rng = np.random.default_rng(scenario.seed)
        self.rotor = scenario.rotor.rotor()
        shaker = Shaker(scenario.shaker.tones(), scenario.shaker.noise_rms_n,
                        self.config.shaker.force_limit_n, seed=int(rng.integers(2**31)),
                        rotor=self.rotor)
        self.plant = PPHPlant(self.config, shaker=shaker, seed=int(rng.integers(2**31)))
        self.actuated = ActuatedPlant(self.plant, self.config.strut, fs)
        self.actuated.test_sine.frequency_hz = scenario.test_sine.frequency_hz
        self.actuated.test_sine.amplitude_n = scenario.test_sine.amplitude_n
        self.pointing = make_pointing_controller(self.config, self.plant.eddy.sensing_matrix, fs)
        self.pointing.set_target(np.asarray(scenario.target_pose),
                                 self.config.strut.stroke_limit_m)
        tones = scenario.notch.tone_frequencies_hz
        z_row = np.linalg.inv(self.config.geometry.top_jacobian)[2]     # the report's z axis
        self.notch = (NotchSupervisor(notch_config(scenario), fs, output_weights=z_row)
                      if tones else None)
        self.tachometer = self.rotor is not None and scenario.rotor.tachometer
        """Whether the rotor's speed (the speed at the sample's time, Hz) is fed to the
        notch as its reference frequency each sample, as the driver publishes it."""
        self.next_sample = 0
        """The sample :meth:`advance` simulates next."""

    def _controller_step(self, n: int, accel_m_s2: np.ndarray,
                         record: LoopRecord) -> np.ndarray:
        """The vibration controller's command (N) for sample ``n`` from the raw accelerations."""
        if self.notch is None:
            return np.zeros(STRUTS)
        if n == record.control_on_sample:
            self.notch.apply({"enabled": True})
        if self.tachometer:
            self.notch.set_reference_frequency(float(self.rotor.speed_hz((n + 1) / self.fs)), n)
        return self.notch.step(n, accel_m_s2)

    def new_record(self) -> LoopRecord:
        """An empty record of the whole scenario, for :meth:`advance` to fill."""
        sc, n_samples = self.scenario, self.scenario.samples
        tones = len(sc.notch.tone_frequencies_hz)
        bank = 0 if self.notch is None else self.notch.canceller.tone_frequencies_hz.size
        return LoopRecord(*(np.zeros((n_samples, STRUTS)) for _ in range(7)),
                          weights=np.zeros((n_samples, bank, STRUTS), complex),
                          control_on_sample=int(round(sc.control_on_s * self.fs)),
                          tone_estimates_hz=np.zeros((n_samples, tones)))

    def advance(self, rec: LoopRecord, stop: int) -> None:
        """Simulate from the next sample up to sample ``stop`` (excluded) into ``rec``.

        A run in pieces is the run in one piece, sample for sample; a piece may change
        ``rec.control_on_sample`` before it (e.g. a twin that never turns control on).
        """
        for n in range(self.next_sample, stop):
            sample = self.actuated.pending
            notch = self._controller_step(n, sample.accel_m_s2, rec)
            pointing = self.pointing.step(sample.eddy_m)
            rec.accel_m_s2[n], rec.eddy_m[n] = sample.accel_m_s2, sample.eddy_m
            rec.notch_command_n[n], rec.pointing_command_n[n] = notch, pointing
            rec.relative_pose_true[n] = sample.relative_pose_true
            rec.top_accel_true[n] = sample.top_accel_true
            if self.notch is not None:
                rec.weights[n] = self.notch.canceller.weights
                rec.tone_estimates_hz[n] = self.notch.tone_estimates_hz
            rec.actuator_force_n[n] = self.actuated.apply(n, notch, pointing)
        self.next_sample = max(self.next_sample, stop)

    def finish(self, record: LoopRecord) -> LoopRecord:
        """Copy the notch's identification and what it reported into ``record``; ``record``."""
        if self.notch is not None:
            record.plant_response = self.notch.plant_response
            if record.plant_response is not None:
                record.coefficients = self.notch.canceller.coefficients
            record.mu_bound = self.notch.bound
            record.notes.extend(event.message for event in self.notch.drain_events())
        return record

    def run(self) -> LoopRecord:
        """Simulate the whole scenario and return every sample."""
        rec = self.new_record()
        self.advance(rec, self.scenario.samples)
        return self.finish(rec)
