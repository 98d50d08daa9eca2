"""The core loop with the supervisor's broadband identification, mu policy and prediction.

:class:`IdentifyingLoop` is a :class:`~hexapod_vibration.core.sim.closed_loop.CoreLoop`
whose notch supervisor identifies G(f) with its
:class:`~hexapod_vibration.core.control.plant_identification.BroadbandIdentifier`
(``identification: broadband``), applies the mu policy (per-tone rates folded into P) and
predicts |S(f)| before control goes on, all on the z axis as the output view (what the
report measures). This helper only reads what the supervisor did. ``enable_control=False``
runs the same timeline (same seeds, same identification) with the output never enabled:
the uncontrolled twin of a run, driven by the same disturbance realization.
:class:`ImpulseLoop` measures the reference G(f) of a quiet plant by impulses.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import signal

from hexapod_vibration.core.control import adaptation, mu_policy, sensitivity
from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.control.plant_identification import (
    DisturbanceSpectrum,
    PlantFrequencyResponse,
)
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.sim.closed_loop import CoreLoop, LoopRecord
from hexapod_vibration.core.sim.scenario import Scenario

FS = 1000.0


class IdentifyingLoop(CoreLoop):
    """CoreLoop with the supervisor's broadband identification and mu policy (the module)."""

    def __init__(self, config: ModelConfig, scenario: Scenario, policy: str = "manual",
                 max_rise_db: float = mu_policy.DEFAULT_MAX_RISE_DB,
                 enable_control: bool = True, guard: bool = True) -> None:
        """The scenario with ``identification: broadband`` and the policy's settings."""
        settings = {**scenario.notch.settings, "identification": "broadband",
                    "mu_policy": policy, "max_rise_db": max_rise_db,
                    "divergence_guard": guard}
        scenario = dataclasses.replace(
            scenario, notch=dataclasses.replace(scenario.notch, settings=settings))
        if not enable_control:
            scenario = dataclasses.replace(scenario, control_on_s=scenario.duration_s)
        super().__init__(config, scenario)
        self.enable_control = enable_control

    @property
    def response(self) -> PlantFrequencyResponse:
        """The supervisor's identified G(f)."""
        return self.notch.plant_frequency_response

    @property
    def disturbance(self) -> DisturbanceSpectrum:
        """The disturbance's CSD the supervisor measured during its identification."""
        return self.notch.disturbance_spectrum

    @property
    def choice(self) -> mu_policy.MuChoice:
        """The supervisor's mu policy result."""
        return self.notch.mu_choice

    @property
    def z_row(self) -> np.ndarray:
        """The supervisor's output view: the z row of J^-1."""
        return self.notch.output_weights

    @property
    def record_coefficients(self) -> np.ndarray:
        """The normalised P at the tones (before the policy's per-tone rates)."""
        tones = self.scenario.notch.tone_frequencies_hz
        return adaptation.normalized_coefficients(self.response.at(tones),
                                                  self.notch.config.adaptation)

    def predict(self, disturbance_csd=None, frequencies_hz=None
                ) -> sensitivity.SensitivityPrediction:
        """|S| of the installed canceller on the identified G, z axis as the output view.

        ``disturbance_csd`` defaults to the one measured during the identification; with
        neither argument this is the supervisor's own ``sensitivity``.
        """
        if disturbance_csd is None and frequencies_hz is None:
            return self.notch.sensitivity
        if disturbance_csd is None:
            disturbance_csd = self.disturbance.at
        return sensitivity.predict_sensitivity(
            self.response.at, self.scenario.notch.tone_frequencies_hz, FS,
            self.notch.canceller.coefficients, self.notch.canceller.mu,
            frequencies_hz=frequencies_hz,
            output_weights=self.z_row, disturbance_csd=disturbance_csd)


class ImpulseLoop(CoreLoop):
    """CoreLoop that runs an :class:`ImpulseIdentifier` from ``identify_at_s`` (no notch)."""

    def __init__(self, config: ModelConfig, scenario: Scenario,
                 identifier: ImpulseIdentifier) -> None:
        """The scenario's plant; the impulses replace the notch's command."""
        super().__init__(config, scenario)
        self.identifier = identifier
        self.start = int(round(scenario.identify_at_s * FS))
        self._dc = DCBlocker(6, FS, self.notch.config.dc_cutoff_hz)

    def _controller_step(self, n: int, accel_m_s2: np.ndarray,
                         record: LoopRecord) -> np.ndarray:
        error = self._dc.step(accel_m_s2)
        if n < self.start or self.identifier.done:
            return np.zeros(6)
        return self.identifier.step(error)


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
            csd[:, i, j] = signal.csd(accel[:, i], accel[:, j], FS, window="hann",
                                      nperseg=nper)[1]
    out = np.empty((frequencies_hz.size, 6, 6), dtype=complex)
    for i in range(6):
        for j in range(6):
            out[:, i, j] = (np.interp(frequencies_hz, f, csd[:, i, j].real)
                            + 1j * np.interp(frequencies_hz, f, csd[:, i, j].imag))
    return out


class ImpulseIdentifier:
    """Reference G(f): an impulse into each strut in turn, the FFT of the errors after it.

    Needs a quiet, linear, noise-free plant (shaker off, sensor noise 0, fine ADC): the
    response to ``amplitude_n`` for one sample on strut j, recorded for ``record_s``, gives
    column j exactly up to the truncation of the slowest modes' tails.
    """

    def __init__(self, record_s: float = 20.0, amplitude_n: float = 20.0) -> None:
        """Six records of ``record_s`` each."""
        self._len = int(round(record_s * FS))
        self._amp = amplitude_n
        self._rec = np.zeros((6, self._len, 6))
        self._n = 0
        self.duration_s = 6 * record_s

    @property
    def done(self) -> bool:
        """True after the six records."""
        return self._n >= 6 * self._len

    def step(self, error: np.ndarray) -> np.ndarray:
        """Record e_n; command the impulse at the first sample of each record."""
        u = np.zeros(6)
        if self.done:
            return u
        j, k = divmod(self._n, self._len)
        self._rec[j, k] = error
        if k == 0:
            u[j] = self._amp
        self._n += 1
        return u

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """(frequencies Hz, G (F, 6, 6)) on the record's FFT grid."""
        spec = np.fft.rfft(self._rec - self._rec[:, -1:, :], axis=1) / self._amp   # (6, F, 6)
        return np.fft.rfftfreq(self._len, 1.0 / FS), np.transpose(spec, (1, 2, 0))


def welch_ratio_db(controlled: np.ndarray, uncontrolled: np.ndarray, segment_s: float = 4.0,
                   window: str = "hann") -> tuple[np.ndarray, np.ndarray]:
    """(f Hz, 10 log10 of the Welch PSD ratio) of two records of the same length."""
    nper = int(segment_s * FS)
    f, p1 = signal.welch(controlled, FS, window=window, nperseg=nper)
    _, p0 = signal.welch(uncontrolled, FS, window=window, nperseg=nper)
    return f, 10.0 * np.log10(p1 / p0)


def windowed_prediction_db(prediction: sensitivity.SensitivityPrediction, bins_hz: np.ndarray,
                           disturbance_psd: np.ndarray | None = None, segment_s: float = 4.0,
                           span_hz: float = 3.0, window: str = "hann") -> np.ndarray:
    """What a Welch ratio (``window``) expects from the predicted z-axis |S|^2 and disturbance PSD.

    The Welch estimate at bin f is the true PSD seen through the window's spectral kernel
    ``|W(f - v)|^2``; near a notch narrower than the bins the kernel matters. Here both the
    controlled PSD ``|S_z|^2 Phi_z`` and the uncontrolled ``Phi_z`` are smoothed by the same
    kernel before their ratio is taken. ``prediction`` must hold ``output`` (|S_z|) on a
    fine grid; ``disturbance_psd`` is the z-axis PSD without control on the same grid
    (None: flat).
    """
    f = prediction.frequencies_hz
    s2 = prediction.values("output") ** 2
    phi = np.ones(f.size) if disturbance_psd is None else np.asarray(disturbance_psd)
    n = int(segment_s * FS)
    win = signal.get_window(window, n)
    out = np.empty(bins_hz.size)
    for m, fb in enumerate(bins_hz):
        sel = np.abs(f - fb) <= span_hz
        nu = f[sel] - fb
        kern = np.abs(np.exp(-2j * np.pi * np.outer(nu / FS, np.arange(n))) @ win) ** 2
        w = kern * np.gradient(f[sel]) * phi[sel]
        out[m] = 10.0 * np.log10(np.sum(w * s2[sel]) / np.sum(w))
    return out
