"""Tones that move: a band that follows each one, and the measured sensitivity.

A fixed-frequency level means nothing for a tone that drifts or spins up: its energy
spreads over the band it sweeps. Here the signal is *dechirped* along the tone's recorded
frequency track f(t): with the analytic signal ``x_a`` (scipy.signal.hilbert),

    y(t) = Re{ x_a(t) exp(-j 2 pi integral_0^t (f(s) - f_ref) ds) },

the tone becomes a steady line at ``f_ref`` (the track's mean over the window) and the
report's one level function (:func:`hexapod_vibration.analysis.levels.tone_levels`) measures
it there: its main-lobe band follows the tone. For a steady track ``y`` is ``x`` itself
(the real part of the analytic signal), so a stationary tone keeps its fixed-band level.

The track comes from ``/pph/disturbance_frequencies`` (the driver's true frequencies), or
from ``/pph/notch_frequencies`` (the controller's estimates) when the truth is not
recorded; messages every few samples are interpolated linearly onto every sample.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from hexapod_vibration.core import spectrum

MATCH_TOLERANCE_HZ = 5.0
"""A true frequency column is a controlled tone's when its median lies this close to the
tone's estimate (or nominal frequency)."""
RATIO_SEGMENT_S = 4.0
"""Welch segment (s) of the measured sensitivity (0.25 Hz bins, a few segments per window)."""
RATIO_WINDOW = "blackmanharris"
"""Sidelobes below -92 dB: a tone's leakage does not pass for a change of the noise around it
(with Hann it reads tens of dB of "sensitivity" beside a tone removed by control)."""
NEAR_TONE_HZ = 5.0
"""The comparison of predicted and measured sensitivity is made within 5 Hz of the tones,
leaving out each tone's and line's main lobe and one bin more (:func:`line_exclusion_hz`)."""


def track_on_samples(message_index: np.ndarray, track_hz: np.ndarray,
                     samples: np.ndarray) -> np.ndarray:
    """One column of frequencies (Hz) recorded at ``message_index`` on the given samples.

    Linear interpolation, held before the first and after the last message; NaN values
    (a column absent from some messages) are left out.
    """
    ok = np.isfinite(track_hz)
    if not np.any(ok):
        raise ValueError("the frequency track has no finite value")
    return np.interp(samples, message_index[ok], track_hz[ok])


def dechirp(x: np.ndarray, track_hz: np.ndarray, fs: float) -> tuple[np.ndarray, float]:
    """(y, f_ref): ``x`` with the tone at ``track_hz`` (per sample) moved to f_ref = mean.

    Args:
        x: signal (any unit), 1-D, one value per sample.
        track_hz: the tone's frequency at each sample (Hz), same length.
        fs: sample rate (Hz).
    """
    track = np.asarray(track_hz, dtype=float)
    f_ref = float(np.mean(track))
    offset = track - f_ref
    if not np.any(offset):
        return np.asarray(x, dtype=float), f_ref
    phase = 2.0 * np.pi * np.cumsum(offset) / fs
    analytic = signal.hilbert(np.asarray(x, dtype=float) - np.mean(x))
    return np.real(analytic * np.exp(-1j * phase)), f_ref


def match_columns(table_hz: np.ndarray, targets_hz: list[float]) -> list[int | None]:
    """For each target (Hz), the column of ``table_hz`` (N, K) whose median is nearest.

    None when no column's median lies within ``MATCH_TOLERANCE_HZ``; a column serves one
    target at most (the nearest one first).
    """
    medians = np.nanmedian(table_hz, axis=0) if table_hz.size else np.zeros(0)
    pairs = sorted((abs(m - t), k, j) for k, t in enumerate(targets_hz)
                   for j, m in enumerate(medians) if np.isfinite(m))
    chosen: list[int | None] = [None] * len(targets_hz)
    used: set[int] = set()
    for distance, k, j in pairs:
        if distance <= MATCH_TOLERANCE_HZ and chosen[k] is None and j not in used:
            chosen[k] = j
            used.add(j)
    return chosen


def ratio_segment_s(controlled: np.ndarray, uncontrolled: np.ndarray, fs: float) -> float:
    """Welch segment (s) of :func:`spectrum_ratio_db`: 4 s, or the shorter window."""
    return min(RATIO_SEGMENT_S, controlled.size / fs, uncontrolled.size / fs)


def line_exclusion_hz(segment_s: float) -> float:
    """Half-width (Hz) left out around a line: its window's main lobe and one bin more."""
    return (spectrum.main_lobe_half_width_bins(RATIO_WINDOW) + 1) / segment_s


def spectrum_ratio_db(controlled: np.ndarray, uncontrolled: np.ndarray, fs: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(f Hz, 10 log10 of the controlled over the uncontrolled Welch PSD), the measured |S|."""
    segment = ratio_segment_s(controlled, uncontrolled, fs)
    f, on = spectrum.power_spectral_density(controlled - controlled.mean(), fs, segment,
                                            RATIO_WINDOW)
    _, off = spectrum.power_spectral_density(uncontrolled - uncontrolled.mean(), fs, segment,
                                             RATIO_WINDOW)
    return f, 10.0 * np.log10(np.maximum(on, 1e-300) / np.maximum(off, 1e-300))


def transfer_function_db(x: np.ndarray, y: np.ndarray, fs: float
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(f Hz, 20 log10 |H1| dB, coherence) of the transfer function from ``x`` to ``y``.

    H1 = Pxy / Pxx (scipy.signal.csd / welch), with the segment and window of
    :func:`spectrum_ratio_db`. With ``x`` a run without control and ``y`` the same samples of
    its twin with control (same disturbance, same noise), H1 is the measured |S(f)|: the
    noise common to both cancels instead of scattering the ratio of two spectra.
    """
    x = np.asarray(x, dtype=float) - np.mean(x)
    y = np.asarray(y, dtype=float) - np.mean(y)
    nperseg = int(round(ratio_segment_s(y, x, fs) * fs))
    options = {"fs": fs, "window": RATIO_WINDOW, "nperseg": nperseg, "noverlap": nperseg // 2,
               "detrend": "constant"}
    f, pxy = signal.csd(x, y, **options)
    _, pxx = signal.welch(x, **options)
    _, pyy = signal.welch(y, **options)
    tiny = 1e-300
    h1 = np.abs(pxy) / np.maximum(pxx, tiny)
    coherence = np.abs(pxy) ** 2 / np.maximum(pxx * pyy, tiny)
    return f, 20.0 * np.log10(np.maximum(h1, tiny)), coherence


def near_tones_mask(f_hz: np.ndarray, tones_hz: list[float], lines_hz: list[float],
                    exclusion_hz: float) -> np.ndarray:
    """Frequencies within ``NEAR_TONE_HZ`` of a tone, more than ``exclusion_hz`` from lines."""
    near = np.zeros(f_hz.size, dtype=bool)
    for tone in tones_hz:
        near |= np.abs(f_hz - tone) <= NEAR_TONE_HZ
    for line in [*tones_hz, *lines_hz]:
        near &= np.abs(f_hz - line) > exclusion_hz
    return near
