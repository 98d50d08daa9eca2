"""Broadband identification of the loop's plant response G(f), 0..fs/2, on the running plant.

G(f) (complex (F, C, C), (m/s^2) per N) is the phasor of error channel i per unit phasor of
command channel j with the command/observation pairing of docs/architecture.md (the
command returned for sample n is held over [n/fs, (n+1)/fs) and first seen in the error of
sample n+1), so it holds everything the canceller sees: ZOH, the loop's delays, the
anti-aliasing filter, the DC blocker and whatever else runs in the loop (pointing
controller, suspension, mounts).

The excitation is a periodic, zippered, odd multisine (Pintelon & Schoukens, *System
Identification: A Frequency Domain Approach*, ch. 2-3): one period of ``P`` samples holds
lines on the odd bins ``k = 1, 3, 5, ...`` of the ``fs/P`` grid only, dealt to the channels in
turn (bin ``k`` belongs to channel ``((k - 1)/2) mod C``), every channel excited at once with
Schroeder phases. Then

- every line belongs to exactly one channel, so column j of G at its lines is exactly
  ``E_i(k) / U_j(k)`` (no matrix inversion, no cross-talk);
- the record is periodic after ``settle_s``, so the DFT of each period has no leakage;
- a disturbance line on the ``fs/P``-Hz even grid (with the default 8 s period: every
  0.25 Hz, so every integer Hz, where the shaker's tones are) falls on an even bin, which
  no channel excites: it does not bias G;
- the unexcited even bins next to a line ("detection lines") measure the noise there, so
  each line's standard error is known even from one period; lines whose error is too
  large (a disturbance tone off the even grid leaking into the lines next to it) are
  dropped and G is interpolated across them.

Each column is known at its own lines (every ``2 C fs/P`` Hz: 1.5 Hz with six channels
and 8 s periods) and is interpolated (cubic spline on real and imaginary parts) to any
frequency. With the defaults (2 s settling, one 8 s period: 10 s) the PPH's G, checked
against its impulse response (noise-free linear plant), is within 0.2 % (median) between
35 and 45 Hz, 0.1 % from 45 to 100 Hz, 0.5 % from 25 to 35 Hz; from 15 to 25 Hz, where the
loop has two resonances about 1 Hz wide (17.7 and 22.5 Hz) between the lines, 20-35 %.
A 12 s period (15 s in all) halves that; the error scales with the line spacing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar
from scipy.sparse.linalg import LinearOperator, gmres

from hexapod_vibration.core.control.adaptation import SampledRun, schroeder_phases
from hexapod_vibration.core.control.held_inputs import held_input_response

DEFAULT_PERIOD_S = 8.0
DEFAULT_SETTLE_S = 2.0
DEFAULT_PERIODS = 1
DEFAULT_AMPLITUDE_RMS_N = 2.0
DEFAULT_MAX_RELATIVE_ERROR = 0.1
DETECTION_NEIGHBOURS = 4
DEFAULT_SMOOTHING_HZ = 4.0
DEFAULT_LINE_FACTOR = 10.0
STRONG_LINE_FACTOR = 100.0
"""A spectral peak this many times the median power is a disturbance line, removed."""
MODEL_ITERATIONS = 30
"""Most GMRES iterations of the modelled record (held inputs, missing samples:
:meth:`BroadbandIdentifier._modelled`)."""
MODEL_TOLERANCE = 1e-4
"""Relative residual at which the modelled record's GMRES stops."""
MAX_REMOVED_LINES = 6
OFF_GRID_GAIN = 0.1
"""A line counts as off the grid only if the off-grid fit leaves less than this fraction of
the residual the on-grid one leaves (a leaking line: most of its power is leakage)."""
ON_GRID_TOLERANCE = 0.05
"""A fitted line closer than this (in record bins) to the DFT grid is on it: it does not
leak, and is left alone."""


@dataclass(frozen=True)
class MultisineDesign:
    """One period of the zippered odd multisine: lines per channel and the command table.

    Attributes:
        sample_rate_hz: loop rate fs (Hz).
        period_samples: samples P in one period (the frequency grid is fs/P Hz).
        bins: excited DFT bins (L,), ascending, all odd.
        channel_of_bin: channel excited at each bin (L,).
        phasors_n: complex amplitude of each line (L,) (N peak, phase rad): the command of
            its channel is ``sum Re{U e^{j 2 pi k n / P}}`` over its lines.
    """

    sample_rate_hz: float
    period_samples: int
    bins: np.ndarray
    channel_of_bin: np.ndarray
    phasors_n: np.ndarray

    @property
    def n_channels(self) -> int:
        """Number of channels C."""
        return int(self.channel_of_bin.max()) + 1

    @property
    def frequencies_hz(self) -> np.ndarray:
        """Frequency of each line (Hz)."""
        return self.bins * self.sample_rate_hz / self.period_samples

    def channel_lines(self) -> list[np.ndarray]:
        """The indices (into ``bins``) of each channel's lines, channel by channel."""
        return [np.flatnonzero(self.channel_of_bin == j) for j in range(self.n_channels)]

    def period_table(self) -> np.ndarray:
        """The commands of one period (P, C) (N), exactly periodic."""
        # sum over the lines b of channel j of Re(A_b exp(2 pi i n b / P)), as one inverse
        # DFT per channel (the lines' bins are below P/2)
        spectrum = np.zeros((self.period_samples, self.n_channels), dtype=complex)
        np.add.at(spectrum, (self.bins, self.channel_of_bin), self.phasors_n)
        return self.period_samples * np.fft.ifft(spectrum, axis=0).real


def zippered_odd_multisine(n_channels: int, sample_rate_hz: float,
                           period_s: float = DEFAULT_PERIOD_S,
                           amplitude_rms_n: float = DEFAULT_AMPLITUDE_RMS_N,
                           min_frequency_hz: float = 0.0,
                           max_frequency_hz: float | None = None) -> MultisineDesign:
    """Design the excitation: odd bins dealt to the channels, Schroeder phases, equal lines.

    Args:
        n_channels: channels C (struts).
        sample_rate_hz: loop rate fs (Hz).
        period_s: period (s); the grid is 1/period_s Hz and each channel gets a line every
            2 C / period_s Hz.
        amplitude_rms_n: RMS command of each channel (N); its lines share it equally.
        min_frequency_hz: lowest excited line (Hz).
        max_frequency_hz: highest excited line (Hz); default fs/2.

    Raises:
        ValueError: a bad argument, or fewer than 2 lines per channel.
    """
    c = int(n_channels)
    fs = float(sample_rate_hz)
    if c != n_channels or c < 1:
        raise ValueError(f"n_channels must be a positive integer, got {n_channels!r}")
    if not np.isfinite(fs) or fs <= 0.0:
        raise ValueError(f"sample_rate_hz must be > 0, got {sample_rate_hz!r}")
    period = int(round(period_s * fs))
    if not np.isfinite(period_s) or period < 4 * c or abs(period - period_s * fs) > 1e-6:
        raise ValueError(f"period_s must be a whole number of samples >= {4 * c}, got "
                         f"{period_s!r} s at {fs:g} Hz")
    if not np.isfinite(amplitude_rms_n) or amplitude_rms_n <= 0.0:
        raise ValueError(f"amplitude_rms_n must be > 0 N, got {amplitude_rms_n!r}")
    f_max = 0.5 * fs if max_frequency_hz is None else float(max_frequency_hz)
    bins = np.arange(1, (period + 1) // 2, 2)
    freqs = bins * fs / period
    keep = (freqs >= min_frequency_hz) & (freqs <= f_max) & (freqs < 0.5 * fs)
    channel = ((bins - 1) // 2) % c
    bins, channel = bins[keep], channel[keep]
    counts = np.bincount(channel, minlength=c)
    if counts.min() < 2:
        raise ValueError(f"the band {min_frequency_hz:g}..{f_max:g} Hz leaves fewer than 2 "
                         "lines for some channel: widen it or lengthen period_s")
    phasors = np.zeros(bins.size, dtype=complex)
    for j in range(c):
        sel = channel == j
        amp = amplitude_rms_n * np.sqrt(2.0 / counts[j])
        phasors[sel] = amp * np.exp(1j * schroeder_phases(int(counts[j])))
    return MultisineDesign(fs, period, bins, channel, phasors)


@dataclass(frozen=True)
class PlantFrequencyResponse:
    """G measured at each column's own lines, interpolated to any frequency on request.

    Attributes:
        sample_rate_hz: loop rate fs (Hz).
        line_frequencies_hz: per column j, the frequencies (Hz) where it was measured.
        line_response: per column j, complex (L_j, C) values G[:, j] at those lines.
        line_relative_error: per column j, (L_j,) standard error of the line's column
            vector (from the detection lines) divided by its norm.
    """

    sample_rate_hz: float
    line_frequencies_hz: tuple[np.ndarray, ...]
    line_response: tuple[np.ndarray, ...]
    line_relative_error: tuple[np.ndarray, ...]

    @property
    def n_channels(self) -> int:
        """Number of channels C."""
        return len(self.line_response)

    def at(self, frequencies_hz: Sequence[float] | np.ndarray) -> np.ndarray:
        """G (F, C, C) at ``frequencies_hz`` (in [0, fs/2]), cubic spline per column.

        Outside a column's measured lines the end line's value is held (the lowest line
        is at fs/P Hz or above, the highest within 2 C fs/P Hz of fs/2).
        """
        f = np.asarray(frequencies_hz, dtype=float).reshape(-1)
        if np.any(~np.isfinite(f)) or np.any(f < 0.0) or np.any(f > 0.5 * self.sample_rate_hz):
            raise ValueError(f"frequencies must be in [0, {0.5 * self.sample_rate_hz:g}] Hz")
        c = self.n_channels
        out = np.empty((f.size, c, c), dtype=complex)
        for j, spline in enumerate(self._splines()):
            lines = self.line_frequencies_hz[j]
            out[:, :, j] = spline(np.clip(f, lines[0], lines[-1]))
        return out

    def _splines(self) -> list[CubicSpline]:
        """One cubic spline per column, built once (the response is immutable)."""
        cached = self.__dict__.get("_spline_cache")
        if cached is None:
            cached = [CubicSpline(lines, g, axis=0) for lines, g in
                      zip(self.line_frequencies_hz, self.line_response, strict=True)]
            object.__setattr__(self, "_spline_cache", cached)
        return cached


    def uncertainty_at(self, frequencies_hz: Sequence[float] | np.ndarray) -> np.ndarray:
        """Relative uncertainty of G at ``frequencies_hz`` (F,): the worst column's.

        Two figures per column, the larger kept: the standard error of the lines there
        (``line_relative_error``, interpolated linearly) and the interpolation's own
        error, estimated by leaving out the measured line nearest to f and comparing the
        two splines (``|G - G_loo| / |G|``, column norms). A disturbance that corrupts the
        lines next to a tone removes them; the wider gap shows up in the second figure.
        """
        f = np.asarray(frequencies_hz, dtype=float).reshape(-1)
        full = self.at(f)
        out = np.zeros(f.size)
        for j in range(self.n_channels):
            lines = self.line_frequencies_hz[j]
            err = np.interp(f, lines, self.line_relative_error[j])
            loo = np.empty((f.size, self.n_channels), dtype=complex)
            for m, fm in enumerate(f):
                keep = np.ones(lines.size, bool)
                keep[int(np.argmin(np.abs(lines - fm)))] = False
                spline = CubicSpline(lines[keep], self.line_response[j][keep], axis=0)
                loo[m] = spline(np.clip(fm, lines[keep][0], lines[keep][-1]))
            col = full[:, :, j]
            interp = (np.linalg.norm(col - loo, axis=1)
                      / np.maximum(np.linalg.norm(col, axis=1), 1e-300))
            out = np.maximum(out, np.maximum(err, interp))
        return out


@dataclass(frozen=True)
class RemovedLine:
    """A disturbance sinusoid fitted in the record and subtracted before the DFT.

    Attributes:
        frequency_hz: its frequency (Hz), fitted to a small fraction of a bin.
        amplitude: (C,) peak amplitude per channel (m/s^2).
    """

    frequency_hz: float
    amplitude: np.ndarray


def _dirichlet(offset_bins: np.ndarray, n: int) -> np.ndarray:
    """DFT at bin k of ``e^{j 2 pi nu m / n}``, m = 0..n-1, as a function of k - nu."""
    x = np.asarray(offset_bins, dtype=float)
    den = np.sin(np.pi * x / n)
    small = np.abs(den) < 1e-12
    ratio = np.where(small, n, np.sin(np.pi * x) / np.where(small, 1.0, den))
    return np.exp(-1j * np.pi * x * (n - 1) / n) * ratio


def _kernel_fit(spectrum: np.ndarray, bins: np.ndarray, nu: float, n: int
                ) -> tuple[np.ndarray, float]:
    """Least-squares phasors A (C,) of a line at bin ``nu`` on ``bins``, residual power."""
    kernel = _dirichlet(bins - nu, n)                                   # (S,)
    amp = kernel.conj() @ spectrum[bins] / np.vdot(kernel, kernel).real  # (C,)
    residual = spectrum[bins] - kernel[:, None] * amp[None, :]
    return amp, float(np.sum(np.abs(residual) ** 2))


def remove_strong_lines(record: np.ndarray, fs: float, design: MultisineDesign,
                        span_hz: float = 8.0) -> tuple[np.ndarray, list[RemovedLine]]:
    """Subtract the disturbance lines that would leak over the excitation (N, C) -> (N, C).

    A disturbance line off the record's DFT grid (a tone a fraction of a hertz from the
    told one) is not periodic in the record: its DFT leaks, as ``1/distance``, over every
    line around it (an 80 N shaker line at 40.4 Hz spoils every line from 30 to 50 Hz).
    The bins the excitation does not use (all but the odd multiples of the period's grid)
    hold only the disturbance and noise, so there its leakage is known exactly: the
    Dirichlet kernel of the record. The strongest local maxima of those bins (channels
    summed) above ``STRONG_LINE_FACTOR`` times their median are candidates; each is fitted
    on the unexcited bins within ``span_hz`` but those of the other strong lines (frequency
    by a bounded 1-D search, phasor per channel by least squares) and, if it lies off the
    DFT grid (and fits there far better than on it, ``OFF_GRID_GAIN``), subtracted from
    the record as a sinusoid, up to ``MAX_REMOVED_LINES``. A line on the grid does not
    leak and is left alone. The excitation lines next to a removed line are dropped by
    :func:`response_from_periods`.
    """
    x = np.asarray(record, dtype=float).copy()
    n = x.shape[0]
    periods = n // design.period_samples
    k = np.arange(n // 2 + 1)
    excited = (k % periods == 0) & ((k // periods) % 2 == 1)
    free = np.flatnonzero(~excited & (k > 1))
    span = int(round(span_hz * n / fs))
    removed: list[RemovedLine] = []
    skipped: set[int] = set()
    t = np.arange(n)
    while len(removed) < MAX_REMOVED_LINES:
        spectrum = np.fft.fft(x, axis=0)
        power = np.sum(np.abs(spectrum[free]) ** 2, axis=1)
        local = np.flatnonzero((power[1:-1] > power[:-2]) & (power[1:-1] >= power[2:])) + 1
        threshold = STRONG_LINE_FACTOR * np.median(power)
        local = [int(c) for c in local[np.argsort(power[local])[::-1]]
                 if power[c] > threshold and int(c) not in skipped]
        if not local:
            break
        k0 = int(free[local[0]])
        strong = free[power > threshold]
        others = strong[np.abs(strong - k0) > 2]
        near = free[(np.abs(free - k0) <= span) & ~np.isin(free, others)]
        fit = minimize_scalar(lambda nu, near=near, sp=spectrum: _kernel_fit(sp, near, nu, n)[1],
                              bounds=(k0 - 1.0, k0 + 1.0), method="bounded",
                              options={"xatol": 1e-6})
        nu = float(fit.x)
        if (abs(nu - round(nu)) < ON_GRID_TOLERANCE
                or fit.fun > OFF_GRID_GAIN * _kernel_fit(spectrum, near, round(nu), n)[1]):
            skipped.add(local[0])                      # on the DFT grid: does not leak
            continue
        amp, _ = _kernel_fit(spectrum, near, nu, n)
        x -= (2.0 * amp[None, :] * np.exp(2j * np.pi * nu * t / n)[:, None]).real
        removed.append(RemovedLine(nu * fs / n, 2.0 * np.abs(amp)))
    return x, removed


def detection_line_noise(spectrum: np.ndarray, bins: np.ndarray,
                         neighbours: int = DETECTION_NEIGHBOURS) -> np.ndarray:
    """Noise magnitude (L, C) at each excited bin from the unexcited even bins around it.

    ``spectrum`` (P, C) holds the phasors of the averaged period. An even bin carries no
    excitation, only what is not periodic in the excitation (noise, disturbances, leakage
    of a tone off the even grid), so ``|E(k')|^2`` there estimates the noise power at the
    odd bins next to it. Two estimates, the larger one kept:

    - the broadband level: the median over ``neighbours`` even bins on each side, divided
      by ln 2 (the median of an exponential variable): robust to a disturbance line;
    - the local level: the smaller of the two adjacent even bins. A tone off the even grid
      leaks into both (and into the odd bin between them); a tone on the grid sits in one
      and leaks into none, and the smaller one ignores it.
    """
    half = spectrum.shape[0] // 2
    even = np.arange(0, half + 1, 2)
    power = np.abs(spectrum[even]) ** 2                                   # (E, C)
    pos = np.searchsorted(even, bins)                                     # even[pos] = k + 1
    out = np.empty((bins.size, spectrum.shape[1]))
    for n, k in enumerate(pos):
        lo, hi = max(k - neighbours, 1), min(k + neighbours, even.size)
        broad = np.median(power[lo:hi], axis=0) / np.log(2.0)
        local = np.minimum(power[k - 1], power[min(k, even.size - 1)])
        out[n] = np.sqrt(np.maximum(broad, local))
    return out


def period_spectrum(error_periods: np.ndarray) -> np.ndarray:
    """The phasors (P, C) of the mean period of ``error_periods`` (M, P, C): DFT x 2/P."""
    return np.fft.fft(error_periods.mean(axis=0), axis=0) * (2.0 / error_periods.shape[1])


def response_from_periods(design: MultisineDesign, error_periods: np.ndarray,
                          max_relative_error: float = DEFAULT_MAX_RELATIVE_ERROR,
                          removed_hz: Sequence[float] = ()) -> PlantFrequencyResponse:
    """G from the errors of M whole periods of steady-state excitation.

    Args:
        design: the excitation that was applied.
        error_periods: errors (M, P, C) (m/s^2), period by period, sample n of a period
            paired with the command of the same sample.
        max_relative_error: lines whose standard error (norm over the column) exceeds
            this fraction of the column's norm are dropped, as long as at least 4 lines
            remain per column (the best ones are kept otherwise). The standard error comes
            from the detection lines (:func:`detection_line_noise`), so it works with one
            period too.
        removed_hz: disturbance lines subtracted from the record
            (:func:`remove_strong_lines`): the lines within 1.5 bins of them are dropped.

    Returns:
        The response at the kept lines of every column.
    """
    e = np.asarray(error_periods, dtype=float)
    m, p, c = e.shape
    if p != design.period_samples or c != design.n_channels:
        raise ValueError(f"error_periods must be (M, {design.period_samples}, "
                         f"{design.n_channels}), got {e.shape}")
    spectrum = period_spectrum(e)                                        # (P, C) phasors
    mean = spectrum[design.bins] / design.phasors_n[:, None]             # (L, C) = E / U
    noise = detection_line_noise(spectrum, design.bins) / np.abs(design.phasors_n)[:, None]
    rel = (np.linalg.norm(noise, axis=1)
           / np.maximum(np.linalg.norm(mean, axis=1), 1e-300))
    freqs = design.frequencies_hz
    record_bin_hz = design.sample_rate_hz / (design.period_samples * m)
    for f_line in removed_hz:
        rel[np.abs(freqs - f_line) <= 1.5 * max(record_bin_hz, design.sample_rate_hz / p)
            ] = np.inf
    lines_f, lines_g, lines_e = [], [], []
    for idx in design.channel_lines():
        good = idx[~(rel[idx] > max_relative_error)]
        if good.size < 4:
            good = np.sort(idx[np.argsort(rel[idx])[:4]])
        lines_f.append(freqs[good])
        lines_g.append(mean[good])
        lines_e.append(rel[good])
    return PlantFrequencyResponse(design.sample_rate_hz, tuple(lines_f), tuple(lines_g),
                                  tuple(lines_e))


@dataclass(frozen=True)
class DisturbanceSpectrum:
    """Cross-spectral density of the error without excitation (no control), per frequency.

    Attributes:
        frequencies_hz: (K,) frequencies (Hz), ascending.
        csd: (K, C, C) Hermitian one-sided cross-spectral density ((m/s^2)^2/Hz).
    """

    frequencies_hz: np.ndarray
    csd: np.ndarray

    def at(self, frequencies_hz: Sequence[float] | np.ndarray) -> np.ndarray:
        """The CSD (F, C, C) at ``frequencies_hz``: linear interpolation, ends held."""
        f = np.asarray(frequencies_hz, dtype=float).reshape(-1)
        k = self.frequencies_hz
        flat = self.csd.reshape(k.size, -1)
        out = np.empty((f.size, flat.shape[1]), dtype=complex)
        for m in range(flat.shape[1]):
            out[:, m] = (np.interp(f, k, flat[:, m].real)
                         + 1j * np.interp(f, k, flat[:, m].imag))
        return out.reshape(f.size, *self.csd.shape[1:])


def disturbance_from_periods(design: MultisineDesign, error_periods: np.ndarray,
                             smoothing_hz: float = DEFAULT_SMOOTHING_HZ,
                             line_factor: float = DEFAULT_LINE_FACTOR) -> DisturbanceSpectrum:
    """The disturbance's CSD from the unexcited even bins of the identification record.

    An even bin holds only what the excitation did not cause: the shaker, sensor noise,
    and so the disturbance the canceller will face. Each bin gives one snapshot ``A A^H``
    (A the (C,) phasors); the CSD is their mean over ``smoothing_hz`` around each bin,
    leaving out bins whose power exceeds ``line_factor`` times the local median (the
    disturbance's lines: the spectrum of the broadband part is wanted, the lines are the
    canceller's tones). Scaled to a one-sided density: ``E|A|^2 P / (2 fs)``.
    """
    e = np.asarray(error_periods, dtype=float)
    p = design.period_samples
    even = np.arange(2, (p + 1) // 2, 2)
    a = np.fft.fft(e, axis=1)[:, even, :] * (2.0 / p)                     # (M, K, C)
    snap = (np.einsum("mki,mkj->kij", a, np.conj(a)) / e.shape[0]
            * (p / (2.0 * design.sample_rate_hz)))
    power = np.einsum("kii->k", snap).real
    df = 2.0 * design.sample_rate_hz / p
    half = max(1, int(round(0.5 * smoothing_hz / df)))
    keep = np.ones(even.size, bool)
    for k in range(even.size):
        lo, hi = max(0, k - 4 * half), min(even.size, k + 4 * half + 1)
        keep[k] = power[k] <= line_factor * np.median(power[lo:hi])
    weights = keep.astype(float)
    kept = snap * weights[:, None, None]
    csum = np.cumsum(np.concatenate([np.zeros((1,) + snap.shape[1:]), kept]), axis=0)
    wsum = np.cumsum(np.concatenate([[0.0], weights]))
    idx = np.arange(even.size)
    lo, hi = np.maximum(idx - half, 0), np.minimum(idx + half + 1, even.size)
    csd = (csum[hi] - csum[lo]) / np.maximum(wsum[hi] - wsum[lo], 1.0)[:, None, None]
    return DisturbanceSpectrum(even * design.sample_rate_hz / p, csd)


def _median_line_error(response: PlantFrequencyResponse) -> float:
    """The median relative standard error of every column's lines."""
    return float(np.median(np.concatenate(response.line_relative_error)))


class BroadbandIdentifier(SampledRun):
    """Measure G(f) over 0..fs/2 on a running plant with a periodic multisine.

    Same step interface as the canceller and
    :class:`~hexapod_vibration.core.control.adaptation.ToneResponseIdentifier` (error of
    sample n in, command of sample n out). The excitation starts at once and runs for
    ``settle_s`` (discarded: the plant's transient) plus ``periods`` whole periods, whose
    errors give G (:func:`response_from_periods`). A disturbance on the even grid (the
    shaker's integer-Hz tones with 2 s periods) or uncorrelated with the excitation (the
    shaker's noise, sensor noise) does not bias G; the latter sets the lines' standard
    error.

    Args:
        n_channels: channels C.
        sample_rate_hz: loop rate (Hz).
        period_s, amplitude_rms_n, min_frequency_hz, max_frequency_hz: the excitation,
            see :func:`zippered_odd_multisine`.
        settle_s: discarded settling time (s); any value works (the excitation is
            periodic from its first sample and the measured periods are re-aligned to it).
        periods: measured periods M (>= 2 gives each line's standard error).
        max_relative_error: see :func:`response_from_periods`.
    """

    def __init__(self, n_channels: int, sample_rate_hz: float,
                 period_s: float = DEFAULT_PERIOD_S, settle_s: float = DEFAULT_SETTLE_S,
                 periods: int = DEFAULT_PERIODS,
                 amplitude_rms_n: float = DEFAULT_AMPLITUDE_RMS_N,
                 min_frequency_hz: float = 0.0, max_frequency_hz: float | None = None,
                 max_relative_error: float = DEFAULT_MAX_RELATIVE_ERROR) -> None:
        """Design the excitation (ValueError on bad arguments) and allocate the record."""
        self.design = zippered_odd_multisine(n_channels, sample_rate_hz, period_s,
                                             amplitude_rms_n, min_frequency_hz,
                                             max_frequency_hz)
        if int(periods) != periods or periods < 1:
            raise ValueError(f"periods must be a positive integer, got {periods!r}")
        if not np.isfinite(settle_s) or settle_s < 0.0:
            raise ValueError(f"settle_s must be >= 0 s, got {settle_s!r}")
        self._c = int(n_channels)
        self._fs = float(sample_rate_hz)
        self._table = self.design.period_table()
        self._p = self.design.period_samples
        self._settle = int(round(settle_s * self._fs))
        self._periods = int(periods)
        self._seg_len = self._settle + self._p * self._periods
        self._total = self._seg_len
        self._record = np.zeros((self._p * self._periods, self._c))
        self._received = np.ones(self._p * self._periods, dtype=bool)
        self._max_rel = float(max_relative_error)
        self._u = np.zeros(self._c)
        self._n = 0
        self._difference: np.ndarray | None = None
        self._cleaned: tuple[np.ndarray, list[RemovedLine]] | None = None
        self._columns = self.design.channel_lines()

    def step(self, error: np.ndarray) -> np.ndarray:
        """Record the error of sample n (m/s^2, (C,)) and return the command (N, (C,))."""
        position = self._position(error)
        if position is None:
            return self._u.copy()
        e, _, k = position
        if k >= self._settle:
            self._record[k - self._settle] = e
        self._u[:] = self._table[self._n % self._p]
        self._n += 1
        return self._u.copy()

    def excitation_ahead(self, samples: int) -> np.ndarray:
        """The commands (N, (samples, C)) of the run's next ``samples`` samples (0 past its end)."""
        ahead = np.arange(self._n, self._n + int(samples))
        rows = self._table[ahead % self._p]
        rows[ahead >= self._total] = 0.0
        return rows

    def _skip_one(self, seg: int, k: int) -> None:
        """A missing sample: marked in the record, filled in before the analysis."""
        if k >= self._settle:
            self._received[k - self._settle] = False
            self.missing += 1

    @property
    def measured_samples(self) -> int:
        """Samples of the record (the measured periods)."""
        return self._record.shape[0]

    def result(self) -> PlantFrequencyResponse:
        """The measured response.

        Raises:
            RuntimeError: if the run is not finished.
        """
        if not self.done:
            raise RuntimeError(f"identification not finished ({100 * self.progress:.0f} %)")
        return self._response(self._cleaned_periods())

    def _response(self, cleaned: tuple[np.ndarray, list[RemovedLine]]
                  ) -> PlantFrequencyResponse:
        """G from aligned periods and the lines removed from them (:meth:`_cleaned_periods`)."""
        periods, removed = cleaned
        return response_from_periods(self.design, periods, self._max_rel,
                                     [line.frequency_hz for line in removed])

    def correct_for_held_inputs(self, difference: np.ndarray) -> None:
        """The input that went in was the design plus ``difference`` (total, C) (N).

        Commands the driver held (:mod:`~hexapod_vibration.core.control.held_inputs`):
        the analysis measures G with the input that went in (:meth:`_modelled`).
        """
        difference = np.asarray(difference, dtype=float)
        if difference.shape != (self._total, self._c):
            raise ValueError(f"difference must have shape ({self._total}, {self._c}), "
                             f"got {difference.shape}")
        self._difference = difference if np.any(difference) else None
        self._cleaned = None

    def disturbance(self, smoothing_hz: float = DEFAULT_SMOOTHING_HZ) -> DisturbanceSpectrum:
        """The disturbance's CSD from the same record (:func:`disturbance_from_periods`).

        Raises:
            RuntimeError: if the run is not finished.
        """
        if not self.done:
            raise RuntimeError(f"identification not finished ({100 * self.progress:.0f} %)")
        return disturbance_from_periods(self.design, self._cleaned_periods()[0], smoothing_hz)

    def removed_lines(self) -> list[RemovedLine]:
        """The disturbance lines subtracted before the DFT (:func:`remove_strong_lines`)."""
        return self._cleaned_periods()[1]

    def disturbance_lines(self) -> list[RemovedLine]:
        """Every strong disturbance line of the record: off the DFT grid and on it.

        The lines :func:`remove_strong_lines` fitted and removed (off the grid), and the
        unexcited bins of the cleaned record that are local maxima above
        ``STRONG_LINE_FACTOR`` times the unexcited bins' median power (a line on the grid,
        e.g. a shaker tone at a multiple of the record's resolution), with their peak
        amplitudes (C,) (m/s^2).

        Raises:
            RuntimeError: if the run is not finished.
        """
        if not self.done:
            raise RuntimeError(f"identification not finished ({100 * self.progress:.0f} %)")
        _, removed = self._cleaned_periods()
        record = self._cleaned_record
        n = record.shape[0]
        spectrum = np.fft.rfft(record, axis=0)
        k = np.arange(spectrum.shape[0])
        excited = (k % self._periods == 0) & ((k // self._periods) % 2 == 1)
        free = np.flatnonzero(~excited & (k > 1))
        power = np.sum(np.abs(spectrum[free]) ** 2, axis=1)
        peak = np.flatnonzero((power[1:-1] > power[:-2]) & (power[1:-1] >= power[2:])) + 1
        strong = peak[power[peak] > STRONG_LINE_FACTOR * np.median(power)]
        on_grid = [RemovedLine(float(free[i] * self._fs / n),
                               2.0 * np.abs(spectrum[free[i]]) / n) for i in strong]
        return list(removed) + on_grid

    def _cleaned_periods(self) -> tuple[np.ndarray, list[RemovedLine]]:
        """The aligned periods with the strong disturbance lines removed (cached).

        With held inputs (:meth:`correct_for_held_inputs`) or missing samples, those of the
        modelled record (:meth:`_modelled`) when it is the better one.
        """
        if self._cleaned is None:
            filled = self._fill(self._record)
            record, removed = remove_strong_lines(filled, self._fs, self.design)
            cleaned = (self._align(record), removed)
            if self._difference is not None or not self._received.all():
                record, cleaned = self._modelled(filled, record, cleaned)
            self._cleaned_record = record
            self._cleaned = cleaned
        return self._cleaned

    def _modelled(self, filled: np.ndarray, record: np.ndarray,
                  cleaned: tuple[np.ndarray, list[RemovedLine]]
                  ) -> tuple[np.ndarray, tuple[np.ndarray, list[RemovedLine]]]:
        """The record as the designed input would have given it, every sample received.

        The input that went in was the design plus the held inputs' difference, and the
        missing samples were filled by a cubic spline (:meth:`_fill`), which misses the
        excitation's response above a few tens of Hz. The lines' values x (G at each line,
        (L, C)) solve ``E(F(G_x * u)) = E(record)``: E the estimate of the lines from a
        record (a DFT at the excited bins over the designed phasors), F the fill, ``G_x *
        u`` the response of the G interpolated from x to the applied input, from rest. A
        linear system close to the identity, solved by GMRES (the plain fixed point
        diverges with a few percent of held inputs). The record, less ``F(G_x * u)`` plus
        the response to the design, is then analysed as any record; kept only if its
        lines' median standard error is below the unmodelled one's.
        """
        settle = self._settle
        designed = self._table[np.arange(self._total) % self._p]
        applied = designed if self._difference is None else designed + self._difference
        lines = self._lines_of(record)

        def model(x: np.ndarray) -> np.ndarray:
            return self._lines_of(self._fill(self._response_to(x.reshape(lines.shape),
                                                               applied)[settle:])).ravel()

        operator = LinearOperator((lines.size, lines.size), dtype=complex, matvec=model)
        solution, _ = gmres(operator, lines.ravel(), x0=lines.ravel(),
                            rtol=MODEL_TOLERANCE, maxiter=MODEL_ITERATIONS)
        x = solution.reshape(lines.shape)
        modelled = (filled - self._fill(self._response_to(x, applied)[settle:])
                    + self._response_to(x, designed)[settle:])
        corrected, removed = remove_strong_lines(modelled, self._fs, self.design)
        latest = (self._align(corrected), removed)
        if (_median_line_error(self._response(latest))
                < _median_line_error(self._response(cleaned))):
            return corrected, latest
        return record, cleaned

    def _lines_of(self, record: np.ndarray) -> np.ndarray:
        """The lines' estimate (L, C) of a record (N, C): E / U at the excited bins."""
        spectrum = period_spectrum(self._align(record))
        return spectrum[self.design.bins] / self.design.phasors_n[:, None]

    def _response_to(self, lines: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """The response (total, C) of the G of ``lines`` (L, C) to ``inputs`` (total, C)."""
        design, columns = self.design, self._columns
        response = PlantFrequencyResponse(
            self._fs, tuple(design.frequencies_hz[i] for i in columns),
            tuple(lines[i] for i in columns), tuple(np.zeros(i.size) for i in columns))
        return held_input_response(response.at, inputs, self._fs)

    def _fill(self, record: np.ndarray) -> np.ndarray:
        """``record`` (N, C) with the missing samples interpolated (cubic, from the others).

        The DFT needs every sample of a period. A gap of a few samples at 1 kHz is short
        against the periods of the strong low-frequency lines, which a cubic interpolation
        follows closely; the excitation's response it misses is modelled
        (:meth:`_modelled`).
        """
        if self._received.all():
            return record
        received = np.flatnonzero(self._received)
        missing = np.flatnonzero(~self._received)
        filled = record.copy()
        filled[missing] = CubicSpline(received, record[received], axis=0)(missing)
        return filled

    def _align(self, record: np.ndarray) -> np.ndarray:
        periods = record.reshape(self._periods, self._p, self._c)
        return np.roll(periods, self._settle % self._p, axis=1)

    def _aligned_periods(self) -> np.ndarray:
        """The measured periods (M, P, C), row n of each paired with table row n.

        The record starts at sample ``settle``, not at a period boundary, so the periods
        are rotated by ``settle mod P``.
        """
        periods = self._record.reshape(self._periods, self._p, self._c)
        return np.roll(periods, self._settle % self._p, axis=1)
