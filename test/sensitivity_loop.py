"""The core loop with broadband identification, the mu policy and the predicted sensitivity.

A test helper until the notch supervisor carries them (issue 12, phase 2): a
:class:`~hexapod_vibration.core.sim.closed_loop.CoreLoop` that, at the scenario's
``identify_at_s``, first measures G(f) with a
:class:`~hexapod_vibration.core.control.plant_identification.BroadbandIdentifier`, then runs
the usual tone identification, applies the mu policy (per-tone rates folded into P) and
predicts |S(f)| before control goes on. ``enable_control=False`` runs the same timeline
(same seeds, same identification) with the output never enabled: the uncontrolled twin of
a run, driven by the same disturbance realization.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import signal

from hexapod_vibration.core.control import mu_policy, sensitivity
from hexapod_vibration.core.control.plant_identification import (
    BroadbandIdentifier,
    PlantFrequencyResponse,
)
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.sim.closed_loop import CoreLoop, LoopRecord, coefficients_for
from hexapod_vibration.core.sim.scenario import Scenario

FS = 1000.0


class IdentifyingLoop(CoreLoop):
    """CoreLoop + broadband G(f) + mu policy + predicted sensitivity (see the module)."""

    def __init__(self, config: ModelConfig, scenario: Scenario, policy: str = 'manual',
                 max_rise_db: float = mu_policy.DEFAULT_MAX_RISE_DB,
                 enable_control: bool = True, broadband: dict | None = None) -> None:
        """Shift the tone identification after the broadband one; keep the rest."""
        self.broadband = BroadbandIdentifier(6, FS, **(broadband or {}))
        self.broadband_start = int(round(scenario.identify_at_s * FS))
        shifted = dataclasses.replace(
            scenario, identify_at_s=scenario.identify_at_s + self.broadband.duration_s)
        super().__init__(config, shifted)
        self.policy, self.max_rise_db, self.enable_control = policy, max_rise_db, enable_control
        self.response: PlantFrequencyResponse | None = None
        self.choice: mu_policy.MuChoice | None = None
        self.z_row = np.linalg.inv(self.config.geometry.top_jacobian)[2]

    def _notch_step(self, n: int, error: np.ndarray, record: LoopRecord) -> np.ndarray:
        if self.notch is not None and not self.broadband.done and n >= self.broadband_start:
            self.notch.step(error)                          # keeps its phase running
            command = self.broadband.step(error)
            if self.broadband.done:
                self.response = self.broadband.result()
            return command
        if (not self.enable_control and self.identifier is None
                and n >= record.control_on_sample):
            return self.notch.step(error)                   # stays disabled: output 0
        return super()._notch_step(n, error, record)

    def _install_coefficients(self, record: LoopRecord) -> None:
        response = self.identifier.result()
        sc = self.scenario
        coefficients, bound = coefficients_for(response, sc.notch.adaptation, sc.notch.mu)
        self.choice = mu_policy.choose_tone_rates(
            self.response.at, sc.notch.tone_frequencies_hz, FS, coefficients, sc.notch.mu,
            policy=self.policy, max_rise_db=self.max_rise_db)
        folded = sensitivity.per_tone_coefficients(coefficients, sc.notch.mu,
                                                   self.choice.tone_mu)
        self.notch.set_coefficients(folded)
        record.plant_response, record.coefficients, record.mu_bound = response, folded, bound
        self.identifier = None

    def predict(self, disturbance_csd=None, frequencies_hz=None) -> sensitivity.SensitivityPrediction:
        """|S| of the installed canceller on the identified G, z axis as the output view."""
        return sensitivity.predict_sensitivity(
            self.response.at, self.scenario.notch.tone_frequencies_hz, FS,
            self.notch.coefficients, self.notch.mu, frequencies_hz=frequencies_hz,
            output_weights=self.z_row, disturbance_csd=disturbance_csd)


def z_axis(config: ModelConfig, record: LoopRecord) -> np.ndarray:
    """Top-plate z acceleration (m/s^2) from the six accelerometers (as the report does)."""
    return config.geometry.platform_from_struts(record.accel_m_s2)[:, 2]


def error_csd(accel: np.ndarray, frequencies_hz: np.ndarray, segment_s: float = 4.0
              ) -> np.ndarray:
    """Welch cross-spectral density (F, 6, 6) of the six accelerations, interpolated."""
    nper = int(segment_s * FS)
    f, _ = signal.welch(accel[:, 0], FS, nperseg=nper)
    csd = np.empty((f.size, 6, 6), dtype=complex)
    for i in range(6):
        for j in range(6):
            csd[:, i, j] = signal.csd(accel[:, i], accel[:, j], FS, window='hann',
                                      nperseg=nper)[1]
    out = np.empty((frequencies_hz.size, 6, 6), dtype=complex)
    for i in range(6):
        for j in range(6):
            out[:, i, j] = (np.interp(frequencies_hz, f, csd[:, i, j].real)
                            + 1j * np.interp(frequencies_hz, f, csd[:, i, j].imag))
    return out
