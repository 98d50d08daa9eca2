"""Spectral analysis of accelerations: tone levels in dB re 1 g, noise floor, distortion.

Tone levels integrate a Welch PSD (4-term Blackman-Harris window, 50 % overlap) over the
window's main lobe and subtract the local noise floor, which makes them independent of
where the tone falls between bins (no scalloping loss) and of the window's noise bandwidth.

Default segment length ``DEFAULT_SEGMENT_S = 10 s`` (0.1 Hz bins at any fs): the
Blackman-Harris main lobe is +-4 bins and its sidelobes are below -92 dB. A tone's
integration band (+-4 bins around its nearest bin) must stay >= 4.5 bins from a neighbour's
centre so that only the neighbour's sidelobes (not its main lobe) leak in; for tones 1 Hz
apart at any position between bins that needs at least 4 + 0.5 + 4.5 = 9 bins per Hz
(segment >= 9 s). 8 s fails when both tones sit half a bin off (leakage -55 dB); 10 s gives
a one-bin margin and separates tones 1 Hz apart by > 90 dB. Longer segments average fewer
segments (noisier floor), so 10 s is the compromise. Signals shorter than one segment are
analysed as one segment of their full length and a :class:`ShortSignalWarning` is issued
(``warnings.warn``; the resolution is then coarser than the 1 Hz guarantee).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from scipy import ndimage, signal, stats

G0 = 9.80665
DEFAULT_SEGMENT_S = 10.0
DEFAULT_WINDOW = "blackmanharris"
DEFAULT_BAND_HZ = 2.0
MIN_FLOOR_BINS = 8
LINE_FACTOR = 20.0
"""A bin is a spectral line (left out of every noise floor) when it is a local maximum more
than 20x (13 dB) above the local floor: white noise in a one-segment Welch PSD (2 degrees of
freedom, the least averaged case) exceeds that with probability e^-20 per bin."""
LINE_MEDIAN_HZ = 2.0
TINY_RMS = 1e-12


class ShortSignalWarning(UserWarning):
    """The signal is shorter than one analysis segment; it was analysed as one segment."""


def to_db_re_g(rms_m_s2: float | np.ndarray) -> float | np.ndarray:
    """Return ``20 log10(rms / 1 g)`` (dB re 1 g) of an RMS acceleration (m/s^2)."""
    rms = np.maximum(np.asarray(rms_m_s2, dtype=float), TINY_RMS)
    db = 20.0 * np.log10(rms / G0)
    return float(db) if db.ndim == 0 else db


@lru_cache(maxsize=16)
def main_lobe_half_width_bins(window: str) -> int:
    """Half-width (bins) of a window's main lobe: its first spectral null, rounded up.

    4 for the 4-term Blackman-Harris, 2 for Hann, 1 for boxcar.
    """
    n, zoom = 256, 64
    w = signal.get_window(window, n)
    mag = np.abs(np.fft.rfft(w, n * zoom))[: 16 * zoom]
    minima = np.flatnonzero((mag[1:-1] <= mag[:-2]) & (mag[1:-1] <= mag[2:])) + 1
    if minima.size == 0:
        raise ValueError(f"cannot find the main lobe of window {window!r}")
    return int(np.ceil(minima[0] / zoom - 0.05))


def _segment_samples(n_samples: int, fs: float, segment_s: float) -> int:
    nperseg = int(round(segment_s * fs))
    if nperseg < 1:
        raise ValueError(f"segment_s={segment_s} is shorter than one sample")
    if n_samples < nperseg:
        warnings.warn(
            f"signal of {n_samples / fs:.3g} s is shorter than one {segment_s:g} s segment: "
            "analysed as one segment (coarser resolution)", ShortSignalWarning, stacklevel=3)
        nperseg = n_samples
    return nperseg


def _welch(x: np.ndarray, fs: float, segment_s: float, window: str
           ) -> tuple[np.ndarray, np.ndarray, int]:
    """Welch PSD plus the segment length actually used (samples)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    if x.size < 8:
        raise ValueError(f"signal too short for a spectrum ({x.size} samples)")
    if not np.all(np.isfinite(x)):
        raise ValueError("signal contains non-finite values")
    nperseg = _segment_samples(x.size, fs, segment_s)
    f, psd = signal.welch(x, fs=fs, window=window, nperseg=nperseg, noverlap=nperseg // 2,
                          detrend="constant", scaling="density", return_onesided=True)
    return f, psd, nperseg


def power_spectral_density(x: np.ndarray, fs: float, segment_s: float = DEFAULT_SEGMENT_S,
                           window: str = DEFAULT_WINDOW) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch PSD (density scaling, 50 % overlap, constant detrend).

    Args:
        x: signal (m/s^2), 1-D.
        fs: sample rate (Hz).
        segment_s: segment length (s); see the module docstring.
        window: scipy window name.

    Returns:
        (f_hz, psd) with psd in (m/s^2)^2/Hz.
    """
    f, psd, _ = _welch(x, fs, segment_s, window)
    return f, psd


def _median_bias(n_samples: int, nperseg: int, window: str) -> float:
    """Median / mean of the Welch PSD of white noise (chi-square with Welch's dof)."""
    step = nperseg - nperseg // 2
    k = 1 + max(0, (n_samples - nperseg) // step)
    w = signal.get_window(window, nperseg)
    rho = np.dot(w[step:], w[: nperseg - step]) / np.dot(w, w)
    dof = 2.0 * k / (1.0 + (2.0 * (1.0 - 1.0 / k) * rho ** 2 if k > 1 else 0.0))
    return float(stats.chi2.median(dof) / dof)


class _Lines:
    """PSD of one signal with main-lobe integration and local noise floor per tone."""

    def __init__(self, x: np.ndarray, fs: float, segment_s: float, window: str) -> None:
        self.fs = float(fs)
        self.f, self.psd, nperseg = _welch(x, fs, segment_s, window)
        self.df = self.f[1] - self.f[0]
        self.hw = main_lobe_half_width_bins(window)
        self.bias = _median_bias(np.size(x), nperseg, window)
        self.lines = self._find_lines()

    def _find_lines(self) -> np.ndarray:
        """Bins of the spectral lines (see LINE_FACTOR): what every floor estimate leaves out.

        Found in the spectrum itself, so a tone's floor does not depend on which other
        tones were asked for.
        """
        size = max(3, 2 * int(round(0.5 * LINE_MEDIAN_HZ / self.df)) + 1)
        local = ndimage.median_filter(self.psd, size=size, mode="nearest") / self.bias
        peak = ndimage.maximum_filter(self.psd, size=3, mode="nearest") == self.psd
        lines = np.flatnonzero(peak & (self.psd > LINE_FACTOR * local))
        return lines[lines > 0]

    def bin_of(self, freqs_hz: Sequence[float] | np.ndarray) -> np.ndarray:
        f = np.asarray(freqs_hz, dtype=float).reshape(-1)
        if np.any(~np.isfinite(f)) or np.any(f <= 0.0) or np.any(f >= 0.5 * self.fs):
            raise ValueError(f"tone frequencies must be in (0, fs/2), got {f.tolist()}")
        return np.rint(f / self.df).astype(int)

    def lobe(self, k: int) -> np.ndarray:
        return np.arange(max(k - self.hw, 0), min(k + self.hw, self.f.size - 1) + 1)

    def floor_psd(self, k: int, excluded: np.ndarray, band_hz: float) -> float:
        """Median PSD near bin k outside every excluded main lobe, debiased to a mean."""
        mask = np.ones(self.f.size, dtype=bool)
        for kk in excluded:
            mask[max(kk - self.hw, 0): kk + self.hw + 1] = False
        mask[0] = False
        half = max(0.5 * band_hz / self.df, self.hw + 1)
        idx = np.arange(self.f.size)
        while True:
            sel = mask & (np.abs(idx - k) <= half)
            if np.count_nonzero(sel) >= MIN_FLOOR_BINS or half > self.f.size:
                break
            half *= 2.0
        if not np.any(sel):
            return 0.0
        return float(np.median(self.psd[sel]) / self.bias)

    def tone_and_floor_power(self, freqs_hz: Sequence[float] | np.ndarray,
                             exclude_hz: Sequence[float] | np.ndarray, band_hz: float
                             ) -> tuple[np.ndarray, np.ndarray]:
        """Main-lobe power and the floor's power in the same bandwidth, (m/s^2)^2 each."""
        bins = self.bin_of(freqs_hz)
        common = np.concatenate([self.lines, self.bin_of(exclude_hz) if len(exclude_hz)
                                 else []]).astype(int)
        lobe_p = np.empty(bins.size)
        floor_p = np.empty(bins.size)
        for m, k in enumerate(bins):
            lobe = self.lobe(k)
            lobe_p[m] = np.sum(self.psd[lobe]) * self.df
            excluded = np.append(common, k)
            floor_p[m] = self.floor_psd(k, excluded, band_hz) * lobe.size * self.df
        return lobe_p, floor_p


def tone_rms(x: np.ndarray, fs: float, freqs_hz: Sequence[float] | np.ndarray,
             segment_s: float = DEFAULT_SEGMENT_S, window: str = DEFAULT_WINDOW,
             band_hz: float = DEFAULT_BAND_HZ) -> np.ndarray:
    """RMS (m/s^2) of each tone's component, noise floor removed.

    The PSD is integrated over the main lobe (+-half-width bins, 4 for Blackman-Harris)
    around each tone's nearest bin; the local floor (median PSD within +-band_hz/2 outside
    the tone's own main lobe and those of the spectral lines found in the spectrum, see
    LINE_FACTOR, widened until 8 bins remain, debiased from median to mean) times the same
    bandwidth is subtracted. The floor does not depend on which other tones are requested.
    Clamped at 1e-12 m/s^2.

    Args:
        x: signal (m/s^2), 1-D.
        fs: sample rate (Hz).
        freqs_hz: tone frequencies (Hz), each in (0, fs/2).
        segment_s: Welch segment (s); see the module docstring for the 10 s default.
        window: scipy window name.
        band_hz: width of the band used for the noise floor (Hz).

    Returns:
        (T,) RMS values (m/s^2).
    """
    lines = _Lines(x, fs, segment_s, window)
    lobe_p, floor_p = lines.tone_and_floor_power(freqs_hz, (), band_hz)
    return np.sqrt(np.maximum(lobe_p - floor_p, TINY_RMS ** 2))


def tone_and_floor_db(x: np.ndarray, fs: float, freqs_hz: Sequence[float] | np.ndarray,
                      segment_s: float = DEFAULT_SEGMENT_S, window: str = DEFAULT_WINDOW,
                      band_hz: float = DEFAULT_BAND_HZ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`tone_levels_db` and :func:`noise_floor_db` of every tone from one spectrum.

    The floor of each tone is ``noise_floor_db(x, fs, f)``: it leaves out the tone's own
    main lobe and the spectral lines found in the spectrum, not the other requested tones,
    so a tone's level and floor do not depend on which other tones are asked for.
    """
    lobe_p, floor_p = _Lines(x, fs, segment_s, window).tone_and_floor_power(freqs_hz, (),
                                                                            band_hz)
    tone = np.sqrt(np.maximum(lobe_p - floor_p, TINY_RMS ** 2))
    floor = np.sqrt(np.maximum(floor_p, TINY_RMS ** 2))
    return np.asarray(to_db_re_g(tone)), np.asarray(to_db_re_g(floor))


def tone_levels_db(x: np.ndarray, fs: float, freqs_hz: Sequence[float] | np.ndarray,
                   segment_s: float = DEFAULT_SEGMENT_S, window: str = DEFAULT_WINDOW,
                   band_hz: float = DEFAULT_BAND_HZ) -> np.ndarray:
    """Tone levels in dB re 1 g (``20 log10(rms / 1 g)``) of :func:`tone_rms`."""
    return np.asarray(to_db_re_g(tone_rms(x, fs, freqs_hz, segment_s, window, band_hz)))


def noise_floor_db(x: np.ndarray, fs: float, freq_hz: float,
                   exclude_hz: Sequence[float] | np.ndarray = (),
                   band_hz: float = DEFAULT_BAND_HZ, segment_s: float = DEFAULT_SEGMENT_S,
                   window: str = DEFAULT_WINDOW) -> float:
    """RMS the local noise floor contributes in one tone's integration bandwidth (dB re 1 g).

    Args:
        x: signal (m/s^2), 1-D.
        fs: sample rate (Hz).
        freq_hz: tone frequency (Hz).
        exclude_hz: other tones whose main lobes are left out of the floor estimate (Hz).
        band_hz: width of the band used for the floor (Hz).
        segment_s: Welch segment (s).
        window: scipy window name.
    """
    lines = _Lines(x, fs, segment_s, window)
    _, floor_p = lines.tone_and_floor_power([freq_hz], list(exclude_hz), band_hz)
    return float(to_db_re_g(np.sqrt(max(floor_p[0], TINY_RMS ** 2))))


def third_octave_bands_hz(low_hz: float, high_hz: float) -> np.ndarray:
    """One-third-octave bands (base 10, IEC 61260) whose centres lie in [low_hz, high_hz].

    Centres ``10^(k/10)`` Hz (nominal 6.3, 8, 10, 12.5, ... Hz), edges a factor
    ``10^(+-1/20)`` from the centre.

    Returns:
        (B, 3) array of ``[centre, lower edge, upper edge]`` (Hz).
    """
    if not 0.0 < low_hz <= high_hz:
        raise ValueError(f"need 0 < low_hz <= high_hz, got {low_hz}, {high_hz}")
    k = np.arange(np.ceil(10.0 * np.log10(low_hz) - 1e-9),
                  np.floor(10.0 * np.log10(high_hz) + 1e-9) + 1)
    centre = 10.0 ** (k / 10.0)
    return np.stack([centre, centre * 10.0 ** -0.05, centre * 10.0 ** 0.05], axis=1)


def band_levels_db(x: np.ndarray, fs: float, bands_hz: np.ndarray,
                   exclude_hz: Sequence[float] | np.ndarray = (),
                   segment_s: float = DEFAULT_SEGMENT_S, window: str = DEFAULT_WINDOW
                   ) -> np.ndarray:
    """Level (dB re 1 g) of the continuous spectrum in each band, tone lines left out.

    The band's power is the mean PSD over its bins (lower edge included, upper excluded)
    outside the main lobes of ``exclude_hz``, times the band's width: the RMS the band's
    broadband content would have without those lines. NaN for a band with no bin left.

    Args:
        x: signal (m/s^2), 1-D.
        fs: sample rate (Hz).
        bands_hz: (B, 2) ``[lower, upper]`` edges or (B, 3) ``[centre, lower, upper]`` (Hz).
        exclude_hz: tone lines whose main lobes are left out (Hz), each in (0, fs/2).
        segment_s: Welch segment (s).
        window: scipy window name.
    """
    bands = np.asarray(bands_hz, dtype=float)
    edges = bands[:, -2:]
    lines = _Lines(x, fs, segment_s, window)
    keep = np.ones(lines.f.size, dtype=bool)
    keep[0] = False
    for k in (lines.bin_of(exclude_hz) if len(exclude_hz) else []):
        keep[lines.lobe(int(k))] = False
    power = np.full(edges.shape[0], np.nan)
    for b, (lo, hi) in enumerate(edges):
        sel = keep & (lines.f >= lo) & (lines.f < hi)
        if np.any(sel):
            power[b] = np.mean(lines.psd[sel]) * (hi - lo)
    with np.errstate(invalid="ignore"):
        db = 20.0 * np.log10(np.maximum(np.sqrt(power), TINY_RMS) / G0)
    return np.where(np.isfinite(power), db, np.nan)


def harmonic_distortion(x: np.ndarray, fs: float, fundamental_hz: float,
                        n_harmonics: int | None = None, segment_s: float = DEFAULT_SEGMENT_S,
                        window: str = DEFAULT_WINDOW) -> dict:
    """Levels of f0, 2 f0, ..., n f0 (those below fs/2) and the total harmonic distortion.

    Args:
        x: signal (m/s^2), 1-D.
        fs: sample rate (Hz).
        fundamental_hz: f0 (Hz).
        n_harmonics: highest harmonic number n (1 = fundamental only); default: every
            harmonic below fs/2 (12 for 40 Hz at 1 kHz).
        segment_s: Welch segment (s).
        window: scipy window name.

    Returns:
        ``{"frequencies_hz": [...], "rms_m_s2": [...], "levels_db": [...],
        "relative_db": [level - fundamental level], "harmonics": number of harmonics
        counted (2 f0 and above), "thd_ratio": sqrt(sum_{k>=2} rms_k^2) / rms_1,
        "thd_percent": 100 * thd_ratio}``.
    """
    if not fundamental_hz > 0.0:
        raise ValueError(f"fundamental must be > 0 Hz, got {fundamental_hz}")
    highest = int(np.ceil(0.5 * fs / fundamental_hz)) if n_harmonics is None else int(n_harmonics)
    k = np.arange(1, highest + 1)
    freqs = fundamental_hz * k
    freqs = freqs[freqs < 0.5 * fs]
    if freqs.size == 0:
        raise ValueError(f"fundamental {fundamental_hz} Hz is not below fs/2")
    rms = tone_rms(x, fs, freqs, segment_s, window)
    levels = np.asarray(to_db_re_g(rms)).reshape(-1)
    thd = float(np.sqrt(np.sum(rms[1:] ** 2)) / rms[0])
    return {"frequencies_hz": freqs.tolist(), "rms_m_s2": rms.tolist(),
            "levels_db": levels.tolist(), "relative_db": (levels - levels[0]).tolist(),
            "harmonics": int(freqs.size - 1), "thd_ratio": thd, "thd_percent": 100.0 * thd}


LEVEL_WINDOW = "blackmanharris"
LEVEL_WINDOW_PER_HZ_S = 4.5
"""Tone level over time: window length (s) times the spacing (Hz) to the nearest other line.

A Blackman-Harris window of length L has its first null at 4/L Hz and every sidelobe
beyond it below -92 dB, so a line 4.5/L Hz away is rejected by more than 92 dB."""
LEVEL_WINDOW_MIN_S = 0.2
LEVEL_WINDOW_MAX_S = 10.0
LEVEL_STEP_S = 0.01
CONVERGENCE_TOLERANCE_DB = 3.0
CONVERGENCE_FINAL_WINDOW_S = 2.0


def level_window_s(freq_hz: float, other_hz: Sequence[float] | np.ndarray = ()) -> float:
    """Window (s) of :func:`tone_level_over_time` for a tone with lines at ``other_hz``.

    The shortest Blackman-Harris window that rejects the nearest other line (and DC, i.e.
    gravity, at ``freq_hz`` away) by more than 92 dB: ``4.5 / spacing``, clipped to
    [0.2, 10] s. 0.2 s for 40 Hz beside 80 Hz, 4.5 s for tones 1 Hz apart.
    """
    others = np.asarray(other_hz, dtype=float).reshape(-1)
    others = others[np.abs(others - freq_hz) > 1e-9]
    spacing = min([float(freq_hz), *np.abs(others - freq_hz).tolist()])
    if not np.isfinite(spacing) or spacing <= 0.0:
        raise ValueError(f"tone frequency must be > 0 Hz, got {freq_hz}")
    return float(np.clip(LEVEL_WINDOW_PER_HZ_S / spacing, LEVEL_WINDOW_MIN_S, LEVEL_WINDOW_MAX_S))


def tone_level_over_time(x: np.ndarray, fs: float, freq_hz: float, window_s: float,
                         index: np.ndarray | None = None, step_s: float = LEVEL_STEP_S
                         ) -> tuple[np.ndarray, np.ndarray]:
    """RMS (m/s^2) of one tone's component over time: THE tone level over time.

    The mean is removed (gravity), the signal is demodulated at the tone
    (``z_n = x_n e^{-j 2 pi f n / fs}``) and averaged over a Blackman-Harris window of
    ``window_s`` centred on each output time; the RMS is ``sqrt(2) |sum w z| / sum w``.
    A line ``d`` Hz away is rejected by more than 92 dB when ``window_s >= 4.5 / d`` (see
    :func:`level_window_s`). Only complete windows are returned: none reaches past either
    end or over a missing sample (no edge transient, no interpolation).

    Args:
        x: signal (m/s^2), 1-D, one value per present sample.
        fs: sample rate (Hz).
        freq_hz: tone frequency (Hz), in (0, fs/2).
        window_s: window length (s).
        index: sample index of each value (increasing); default ``0..N-1``. Gaps are
            missing samples.
        step_s: spacing of the output times (s).

    Returns:
        (t_s, rms): window-centre times (s, sample n at n / fs) and RMS (m/s^2).
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    if not 0.0 < freq_hz < 0.5 * fs:
        raise ValueError(f"tone frequency must be in (0, fs/2), got {freq_hz}")
    n_win = max(2, int(round(window_s * fs)))
    idx = np.arange(x.size) if index is None else np.asarray(index, dtype=np.int64)
    if idx.shape != x.shape:
        raise ValueError("index and x must have the same length")
    if x.size == 0 or int(idx[-1] - idx[0]) + 1 < n_win:
        return np.zeros(0), np.zeros(0)
    grid = np.zeros(int(idx[-1] - idx[0]) + 1, dtype=complex)
    present = np.zeros(grid.size)
    n = idx - idx[0]
    grid[n] = (x - x.mean()) * np.exp(-2j * np.pi * freq_hz * n / fs)
    present[n] = 1.0
    w = signal.get_window(LEVEL_WINDOW, n_win, fftbins=False)
    step = max(1, int(round(step_s * fs)))
    avg = signal.fftconvolve(grid, w[::-1], mode="valid")[::step] / w.sum()
    complete = signal.fftconvolve(present, np.ones(n_win), mode="valid")[::step] > n_win - 0.5
    centre = idx[0] + np.arange(avg.size) * step + 0.5 * (n_win - 1)
    return centre[complete] / fs, np.sqrt(2.0) * np.abs(avg[complete])


def convergence_time_s(t_s: np.ndarray, level_db: np.ndarray, t_on_s: float,
                       final_window_s: float = CONVERGENCE_FINAL_WINDOW_S,
                       tolerance_db: float = CONVERGENCE_TOLERANCE_DB) -> float:
    """THE convergence time (s): from ``t_on_s`` until the level first nears its end.

    The time from ``t_on_s`` until the level first comes within ``tolerance_db`` of its
    final level.

    The final level is the mean power (in dB) of ``level_db`` over the last
    ``final_window_s``. First passage, not "stays within": a tone cancelled down to the
    noise floor has a Rayleigh-distributed level that leaves any 3 dB band around its mean
    again and again, which is not a lack of convergence.

    Args:
        t_s: times (s), increasing.
        level_db: levels (dB) at those times.
        t_on_s: time control was switched on (s).
        final_window_s: length of the final window (s).
        tolerance_db: allowed distance from the final level (dB).

    Returns:
        The duration (s), or NaN if there is no level after ``t_on_s``.
    """
    t = np.asarray(t_s, dtype=float)
    lev = np.asarray(level_db, dtype=float)
    if t.shape != lev.shape or t.ndim != 1:
        raise ValueError("t_s and level_db must be 1-D arrays of the same length")
    if t.size == 0:
        return float("nan")
    final_sel = (t >= t[-1] - final_window_s) & np.isfinite(lev)
    if not np.any(final_sel):
        return float("nan")
    final = 10.0 * np.log10(np.mean(10.0 ** (lev[final_sel] / 10.0)))
    inside = np.flatnonzero((np.abs(lev - final) <= tolerance_db) & (t >= t_on_s))
    return float(t[inside[0]] - t_on_s) if inside.size else float("nan")


def tone_convergence(x: np.ndarray, fs: float, freq_hz: float, on_sample: int,
                     other_hz: Sequence[float] | np.ndarray = (),
                     index: np.ndarray | None = None) -> dict:
    """Level over time and convergence of one tone after control-on at ``on_sample``.

    Uses :func:`tone_level_over_time` with :func:`level_window_s` and
    :func:`convergence_time_s`: the one definition shared by the reports, the plots and
    the benchmark.

    Returns:
        ``{"t_s", "level_db" (dB re 1 g), "window_s", "convergence_s", "final_level_db"}``.
    """
    window = level_window_s(freq_hz, other_hz)
    t, rms = tone_level_over_time(x, fs, freq_hz, window, index)
    level = np.asarray(to_db_re_g(rms), dtype=float).reshape(-1)
    conv = convergence_time_s(t, level, on_sample / fs)
    final = t >= (t[-1] - CONVERGENCE_FINAL_WINDOW_S) if t.size else t > 0
    final_db = (float(10.0 * np.log10(np.mean(10.0 ** (level[final] / 10.0))))
                if np.any(final) else float("nan"))
    return {"t_s": t, "level_db": level, "window_s": window, "convergence_s": conv,
            "final_level_db": final_db}
