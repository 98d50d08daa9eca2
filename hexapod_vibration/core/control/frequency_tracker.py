"""Online frequency estimation of the canceller's tones from the rotation of its weights.

A tone whose oscillator runs at ``f`` while the disturbance sits at ``f + df`` makes the
converged weight rotate at ``2 pi df`` (paper eq. 21): ``W`` follows the target
``T = -D/G e^{j 2 pi df t}`` with the adaptation's first-order lag, so the weight lags the
target by the angle ``e`` and turns by ``mu e`` per sample (normalised ``P``, rate ``mu``).
The change of the weights over a block of ``B`` samples gives the residual at the tone,
and its component in quadrature with the canceller's output (both seen through the
identified plant, :func:`weight_phase_error`) is the phase error ``e`` between oscillator
and disturbance: the phase detector of a phase-locked loop whose proportional path is
the adaptation itself. :class:`FrequencyTracker`
closes a phase-locked loop on it (Bodson & Douglas 1997 for the adaptive-notch PLL idea):
per tone the frequency integrates ``K2 e`` plus a learnt rate (which integrates ``K3 e``)
and the next block's per-sample phase increment gets ``K1 e`` on top, so the oscillators
stay phase-continuous (the correction is a frequency offset for ``B`` samples, never a
step) and the weights are kept. With ``alpha = K1 + mu``, without K3 this is a type-2 loop
of natural frequency ``sqrt(K2)`` rad/sample and damping ``alpha / (2 sqrt(K2))``, which
leaves ``e = r / K2`` on a frequency ramp of ``r`` (rad/sample^2), a residual of about
``20 log10(e)`` dB relative to the tone; the slow K3 (corner :data:`RAMP_FRACTION` of the
natural frequency) removes that in steady ramps too. A constant offset leaves none.

Safety: a tone whose weights are frozen, (near) zero or still growing from zero gives no
measurement and its frequency is held. Every tone stays within ``nominal +- range_hz``
and, so that close tones never merge, on its own side of the midpoints between adjacent
nominal tones (at least :data:`MIN_SEPARATION_HZ` from them).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

TWO_PI = 2.0 * np.pi
DEFAULT_BANDWIDTH_HZ = 1.5
"""Natural frequency of the tracking loop (Hz). 2 Hz already oscillates (about 1 Hz) at 30 Hz
on the PPH plant, whose modes near there slow the loop; 1.5 Hz does not."""
DEFAULT_DAMPING = 0.7
RAMP_FRACTION = 0.2
"""The frequency-rate integrator's corner as a fraction of the loop's natural frequency:
a slow third pole that learns a steady ramp (spin-up) so that it leaves no phase error."""
DEFAULT_BLOCK_SAMPLES = 16
"""Samples between two updates of the estimates (the cost is paid once per block)."""
NEIGHBOUR_BANDWIDTH_RATIO = 0.25
"""A tone's loop bandwidth is at most this fraction of the distance (Hz) to the nearest
oscillator of another tone: a faster loop would take the neighbour's residual, which beats
at that distance in its phase detector, for its own phase error (39 and 40 Hz: 0.25 Hz)."""
MIN_SEPARATION_HZ = 0.1
"""Smallest distance (Hz) a tracked tone keeps from the midpoint to its nominal neighbour."""
WEIGHT_FLOOR_N = 1e-9
"""Weights (N, 2-norm over channels) below this carry no phase: no measurement."""
MAX_GROWTH = 1.5
"""A weight whose norm changes by more than this factor over a block (being reset, set)
gives no measurement. (Weights still converging from zero are left out by the caller:
see :data:`SETTLE_TIME_CONSTANTS`; a tighter test here would select blocks by the
direction of their noise and bias the estimate.)"""
SETTLE_TIME_CONSTANTS = 1.0
"""Adaptation time constants (1/mu samples) after adaptation starts before the weights
are measured: before that they are still converging from zero. Meanwhile the tones coast
on the rate acquired at control on. (Two, 2.3 s at the drift scenario's rate, left a
line drifting at 0.25 Hz/s 0.23 Hz from its coasting tone when the loop closed, and the
pull-in swung the tone +-0.8 Hz for 2 s; with one, 0.05 Hz and 0.3 s.)"""
MAX_SLEW_HZ_PER_S = 4.0
"""Fastest change of a tracked frequency (Hz/s): a rotor spinning up at 1 Hz/s moves its
fundamental at 1 Hz/s; a loop pulling in from a large initial error (its phase detector
saturated) would otherwise jump by Hz in a few blocks and splatter images of the tone at
the block rate's multiples."""
PROPORTIONAL_CORNER_HZ = DEFAULT_BANDWIDTH_HZ
"""Corner (Hz) of the first-order low-pass on the phase error of the proportional path:
the loop's own bandwidth.

The proportional correction ``K1 e`` shifts the phase of the canceller's output, which is
as large as the cancelled tone: broadband error in the block's phase detector (up to half
the block rate, 31 Hz, from the tone) is re-emitted beside the tone. Measured on the core
loop against the uncontrolled twin (last 10 s, z axis, largest third-octave rise):
``mismatch_tracking`` +3.6 dB unfiltered, +0.7 dB at 1.5 Hz (a fixed notch on the true
40.4 Hz: +0.66 dB); ``drift`` + tracking +6.1 dB at 8 Hz, +4.0 dB at 3 Hz, +3.1 dB at
1.5 Hz, the tone's band 42.3 dB down in each; ``spin_up`` unchanged. (Before the tones
coasted on the acquired rate, a 3 Hz corner lost the drifting tone.)"""
RATE_BANDWIDTH_MULTIPLE = 8.0
"""A tone's loop is at most this many times as fast as its weights: natural frequency and
proportional corner at most this x ``mu_k fs / (2 pi k)`` of its slowest order k
(:func:`rate_bandwidth_caps_hz`, :meth:`FrequencyTracker.limit_bandwidth`).

The loop closes a second feedback path on the tone (its phase, in quadrature, through the
oscillator) that the predicted sensitivity, and so the mu policy's bound, leaves out. At
1.5 Hz beside weights at mu 0.0006-0.0009 (0.1-0.14 Hz) it was the larger one: core loop
against the twin, ``mismatch_tracking`` with the shaker at 41.0 / 41.5 Hz, the 44.7-56.2 Hz
third octave +1.10 / +1.16..+1.46 dB (a fixed notch on 41.0 Hz: +0.18 dB), the tone 62 / 43
dB down; with this 8 (1.03 / 0.76 Hz) +0.69 / +0.67..+0.75 dB, 65.7 / 57-60 dB;
``drift_tracking`` 44.8 -> 42.8 dB; ``spin_up`` (rates 0.0033-0.006) unchanged. A flat
1.0 Hz kept ``spin_up`` order 2 at 25 dB in the ramp's first second (30 required)."""
MAX_PHASE_ERROR_RAD = 0.5
"""A measured phase error above this (rad) is clipped: the linear loop holds to there."""


def tracking_bounds_hz(nominal_hz: Sequence[float] | np.ndarray, range_hz: float,
                       sample_rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest frequency (Hz) each tone may be tracked to, (T,) each.

    ``nominal +- range_hz``, cut at the midpoints between adjacent nominal tones (minus
    :data:`MIN_SEPARATION_HZ`) so that two tones can never meet, and inside (0, fs/2).

    Raises:
        ValueError: a negative or non-finite range.
    """
    f = np.asarray(nominal_hz, dtype=float).reshape(-1)
    r = float(range_hz)
    if not np.isfinite(r) or r < 0.0:
        raise ValueError(f"tracking_range_hz must be finite and >= 0, got {range_hz!r}")
    lower, upper = f - r, f + r
    order = np.argsort(f)
    sorted_f = f[order]
    if f.size > 1:
        mid = 0.5 * (sorted_f[1:] + sorted_f[:-1])
        gap = np.minimum(MIN_SEPARATION_HZ, 0.25 * np.diff(sorted_f))
        lo_sorted = np.concatenate([[-np.inf], mid + gap])
        hi_sorted = np.concatenate([mid - gap, [np.inf]])
        lower[order] = np.maximum(lower[order], lo_sorted)
        upper[order] = np.minimum(upper[order], hi_sorted)
    edge = 1e-3 * sample_rate_hz
    lower = np.maximum(lower, np.minimum(edge, f))
    upper = np.minimum(upper, np.maximum(0.5 * sample_rate_hz - edge, f))
    return lower, upper


def loop_bandwidths_hz(nominal_hz: Sequence[float] | np.ndarray, orders: Sequence[float],
                       bandwidth_hz: float = DEFAULT_BANDWIDTH_HZ) -> np.ndarray:
    """Each tone's loop bandwidth (Hz): ``bandwidth_hz``, lowered near other tones.

    Order ``k`` of tone ``t`` at distance ``d`` from an oscillator of another tone limits
    the tone's bandwidth to :data:`NEIGHBOUR_BANDWIDTH_RATIO` ``d / k`` (order k's phase
    error is k times the fundamental's).
    """
    f = np.asarray(nominal_hz, dtype=float).reshape(-1)
    k = np.asarray(orders, dtype=float).reshape(-1)
    bank = k[:, None] * f[None, :]                                  # (K, T)
    out = np.full(f.size, float(bandwidth_hz))
    for t in range(f.size):
        others = np.delete(bank, t, axis=1).reshape(-1)
        if others.size:
            d = np.abs(bank[:, t][:, None] - others[None, :]).min(axis=1)     # (K,)
            out[t] = min(out[t], float(np.min(NEIGHBOUR_BANDWIDTH_RATIO * d / k)))
    return out


def rate_bandwidth_caps_hz(orders: Sequence[float] | np.ndarray,
                           tone_mu: Sequence[float] | np.ndarray,
                           sample_rate_hz: float) -> np.ndarray:
    """Each tone's largest loop bandwidth (Hz) for the rates its weights adapt at.

    :data:`RATE_BANDWIDTH_MULTIPLE` x ``mu_k fs / (2 pi k)`` of its slowest order k (the
    weights' loop bandwidth, in the fundamental's frequency). ``tone_mu`` holds one rate per
    oscillator, order-major as the bank (row ``k * T + t``: order k + 1 of tone t).
    """
    k = np.asarray(orders, dtype=float).reshape(-1)
    rates = np.asarray(tone_mu, dtype=float).reshape(k.size, -1) / k[:, None]
    return RATE_BANDWIDTH_MULTIPLE * rates.min(axis=0) * float(sample_rate_hz) / TWO_PI


def weight_phase_error(previous: np.ndarray, current: np.ndarray, rate: float,
                       samples: int, plant: np.ndarray,
                       inverse_coefficients: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phase error (rad) of each oscillator from its weights' change over a block.

    The weights moved by ``dW = mu P sum_n e_n e^{-j phi_n}``, so the block's residual
    phasor (m/s^2) is ``E = 2 P^-1 dW / (mu B)``; the canceller's output seen through the
    plant is ``y = G W(n - B)``. A disturbance that turned by ``psi`` relative to the oscillator
    leaves ``E = -j psi y`` (to first order, once ``W`` has converged), so

        psi = -Im(y^H E) / |y|^2

    whatever the coupling between channels (the weights' own turn, ``Im(W^H dW)``, weighs
    it by ``diag(1/G_ii) G`` in decentralized mode, which is not 1 on a coupled plant).

    Args:
        previous: complex (T, C) weights (N) ``samples`` samples ago.
        current: complex (T, C) weights now.
        rate: the adaptation rate mu the weights moved with.
        samples: samples between the two (B >= 1).
        plant: complex (T, C, C) plant responses G at the oscillators, (m/s^2)/N.
        inverse_coefficients: complex (T, C, C) inverses of the coefficients P.

    Returns:
        ``(error_rad, strength)``: (T,) phase errors (0 where there is no measurement) and
        (T,) weights of the measurements, ``|y|^2`` ((m/s^2)^2; 0 = no measurement:
        frozen, zero or jumping weights, or ``rate`` 0).
    """
    t = current.shape[0]
    if rate <= 0.0 or samples < 1:
        return np.zeros(t), np.zeros(t)
    residual = np.einsum("tij,tj->ti", inverse_coefficients, current - previous)
    # y from the weights before the block: the block's own change is proportional to E,
    # and through a coupled G its cross term Im(E^H (G P)^H E) would bias psi by the
    # residual's power (a weak tone beside strong lines then drifts off its frequency)
    y = np.einsum("tij,tj->ti", plant, previous)
    y_conj = np.conj(y)
    y2 = np.einsum("ti,ti->t", y_conj, y).real
    p2 = np.einsum("ti,ti->t", np.conj(previous), previous).real
    growth = np.einsum("ti,ti->t", np.conj(current), current).real
    growth /= np.maximum(p2, WEIGHT_FLOOR_N ** 2)
    valid = ((p2 > WEIGHT_FLOOR_N ** 2) & (y2 > 0.0) & (growth <= MAX_GROWTH ** 2)
             & (growth >= MAX_GROWTH ** -2))
    cross = np.einsum("ti,ti->t", y_conj, residual).imag
    cross *= -2.0 / (rate * samples)
    error = cross / np.where(valid, y2, np.inf)
    np.clip(error, -MAX_PHASE_ERROR_RAD, MAX_PHASE_ERROR_RAD, out=error)
    return error, y2 * valid


def combine_orders(error_rad: np.ndarray, strength: np.ndarray,
                   orders: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One phase error per fundamental from the errors of its harmonic orders.

    Order ``k`` follows ``k`` times its fundamental, so its phase error is ``k`` times the
    fundamental's: the combination is the least-squares estimate
    ``sum_k s_k k e_k / sum_k s_k k^2`` with ``s_k`` the measurements' strengths.

    Args:
        error_rad: (K, T) phase errors of order row k for tone column t.
        strength: (K, T) their weights (0 = no measurement).
        orders: (K,) the orders (1 first).

    Returns:
        ``(error_rad, valid)`` of the fundamentals, (T,) each.
    """
    if error_rad.shape[0] == 1:                 # one order: its own measurement
        return error_rad[0], strength[0] > 0.0
    k = np.asarray(orders, dtype=float)[:, None]
    den = np.sum(strength * k * k, axis=0)
    valid = den > 0.0
    num = np.sum(strength * k * error_rad, axis=0)
    return np.where(valid, num / np.where(valid, den, 1.0), 0.0), valid


class FrequencyTracker:
    """Type-2 frequency loops, one per tone, on the canceller's weight rotation.

    Args:
        nominal_hz: the tones' nominal frequencies (Hz), (T,).
        range_hz: largest deviation from nominal (Hz), >= 0.
        sample_rate_hz: loop rate fs (Hz).
        bandwidth_hz: the loop's natural frequency (Hz), one for all or (T,) per tone
            (see :func:`loop_bandwidths_hz`).
        damping: the loop's damping ratio.
        block_samples: samples per update (the caller calls :meth:`update` once per block).
    """

    def __init__(self, nominal_hz: Sequence[float] | np.ndarray, range_hz: float,
                 sample_rate_hz: float,
                 bandwidth_hz: float | np.ndarray = DEFAULT_BANDWIDTH_HZ,
                 damping: float = DEFAULT_DAMPING,
                 block_samples: int = DEFAULT_BLOCK_SAMPLES) -> None:
        """Start every tone at its nominal frequency."""
        self.fs = float(sample_rate_hz)
        self.nominal_hz = np.asarray(nominal_hz, dtype=float).reshape(-1).copy()
        self.range_hz = float(range_hz)
        self.lower_hz, self.upper_hz = tracking_bounds_hz(self.nominal_hz, range_hz, self.fs)
        if int(block_samples) < 1:
            raise ValueError(f"block_samples must be >= 1, got {block_samples!r}")
        self.block_samples = int(block_samples)
        self._damping = float(damping)
        self._bandwidth_hz = np.broadcast_to(np.asarray(bandwidth_hz, float),
                                             self.nominal_hz.shape).copy()
        self._set_gains(self._bandwidth_hz, PROPORTIONAL_CORNER_HZ)
        self._rate = np.zeros(self.nominal_hz.size)         # rad/sample per sample
        self._max_step = TWO_PI * MAX_SLEW_HZ_PER_S * self.block_samples / self.fs ** 2
        self._lo = TWO_PI * self.lower_hz / self.fs         # bounds, rad/sample
        self._hi = TWO_PI * self.upper_hz / self.fs
        self._omega = TWO_PI * self.nominal_hz / self.fs     # integrator (rad/sample)
        self._effective = self._omega.copy()
        self._e_smooth = np.zeros(self.nominal_hz.size)     # low-passed phase error (rad)

    def _set_gains(self, bandwidth_hz: np.ndarray, corner_hz: float | np.ndarray) -> None:
        """The loop gains for natural frequencies ``bandwidth_hz`` (Hz, (T,)).

        K1 + mu, K2, K3 per sample and per block; the proportional path's low-pass at
        ``corner_hz`` (Hz).
        """
        omega_n = TWO_PI * np.asarray(bandwidth_hz, float) / self.fs
        self._alpha = 2.0 * self._damping * omega_n         # K1 + mu (rad per rad)
        self._beta = omega_n * omega_n                      # K2 (rad/sample per rad/sample)
        self._gamma = self._beta * RAMP_FRACTION * omega_n  # K3 (rate per rad)
        self._beta_b = self._beta * self.block_samples      # per block
        self._gamma_b = self._gamma * self.block_samples
        self._k1_rate = float("nan")                        # K1 = alpha - mu, cached
        self._k1 = self._alpha
        self._smoothing = -np.expm1(-TWO_PI * np.asarray(corner_hz, float)
                                    * self.block_samples / self.fs)

    def limit_bandwidth(self, cap_hz: float | np.ndarray) -> None:
        """Natural frequencies and proportional corner at most ``cap_hz`` (Hz, one or (T,)).

        The loops keep their state (frequencies, learnt rates); the bandwidths they were
        built with (and :data:`PROPORTIONAL_CORNER_HZ`) come back where the cap is above
        them (:func:`rate_bandwidth_caps_hz`: the weights' rates).
        """
        cap = np.broadcast_to(np.asarray(cap_hz, float), self.nominal_hz.shape)
        self._set_gains(np.minimum(self._bandwidth_hz, cap),
                        np.minimum(PROPORTIONAL_CORNER_HZ, cap))

    @property
    def bandwidths_hz(self) -> np.ndarray:
        """Each loop's natural frequency (Hz) in force, a new array."""
        return np.sqrt(self._beta) * (self.fs / TWO_PI)

    def reset(self, frequencies_hz: Sequence[float] | np.ndarray | None = None,
              rates_hz_per_s: Sequence[float] | np.ndarray | None = None) -> None:
        """Set every loop's frequency (Hz; None: nominal), clamped to the bounds.

        ``rates_hz_per_s``: each tone's present rate of change (Hz/s; None: 0), the
        learnt ramp the loop starts with (and coasts on, :meth:`update`).
        """
        f = self.nominal_hz if frequencies_hz is None else np.asarray(frequencies_hz, float)
        f = np.clip(f, self.lower_hz, self.upper_hz)
        self._omega = TWO_PI * f / self.fs
        self._effective = self._omega.copy()
        rate = np.zeros(self.nominal_hz.size) if rates_hz_per_s is None else np.nan_to_num(
            np.asarray(rates_hz_per_s, dtype=float).reshape(self.nominal_hz.shape))
        self._rate = np.clip(TWO_PI * rate / self.fs ** 2,
                             -self._max_step / self.block_samples,
                             self._max_step / self.block_samples)
        self._e_smooth = np.zeros(self.nominal_hz.size)

    def recentre(self, frequencies_hz: Sequence[float] | np.ndarray,
                 rates_hz_per_s: Sequence[float] | np.ndarray | None = None) -> None:
        """Track from ``frequencies_hz`` (Hz, (T,)) within ``range_hz`` of them from now on.

        A tachometer that goes stale leaves the tones wherever the reference had them (a
        spin-up: far outside nominal +- range); the loops continue from there, bounded
        around there (:func:`tracking_bounds_hz` of those frequencies, so that the tones
        still never merge), at ``rates_hz_per_s`` (Hz/s, the reference's; None: 0).
        """
        f = np.asarray(frequencies_hz, dtype=float).reshape(self.nominal_hz.shape)
        self.lower_hz, self.upper_hz = tracking_bounds_hz(f, self.range_hz, self.fs)
        self._lo = TWO_PI * self.lower_hz / self.fs
        self._hi = TWO_PI * self.upper_hz / self.fs
        self.reset(f, rates_hz_per_s)

    def update(self, error_rad: np.ndarray, valid: np.ndarray, rate: float,
               coast: bool = False) -> np.ndarray:
        """Take one block's phase errors; the frequencies (Hz) for the next block.

        Args:
            error_rad: (T,) phase errors measured over the last block (rad).
            valid: (T,) which of them are measurements (the others hold their tone).
            rate: the adaptation rate mu in force (its share of the proportional gain).
            coast: tones without a measurement go on at their learnt rate of change
                instead of holding (weights still settling after control on: a drifting
                line keeps moving meanwhile).

        Returns:
            (T,) per-sample frequencies (Hz) for the next block: the integrator plus the
            proportional phase correction, within the bounds (a new array).
        """
        lo, hi = self._lo, self._hi
        gate = np.asarray(valid, dtype=float)
        e = error_rad * gate
        if rate != self._k1_rate:
            self._k1, self._k1_rate = np.maximum(self._alpha - float(rate), 0.0), rate
        k1 = self._k1
        self._rate += self._gamma_b * e
        step = self._beta_b * e
        step += self._rate * (self.block_samples * (1.0 if coast else gate))
        np.clip(step, -self._max_step, self._max_step, out=step)
        omega = self._omega + step
        outside = (omega < lo) | (omega > hi)
        if outside.any():                               # anti-windup at the bounds
            self._rate[outside] = 0.0
            np.clip(omega, lo, hi, out=omega)
        self._omega = omega
        self._e_smooth += self._smoothing * (e - self._e_smooth)
        self._e_smooth *= gate              # no measurement: the correction ends, as K1 e
        effective = omega + k1 * self._e_smooth
        np.clip(effective, self._effective - self._max_step, self._effective + self._max_step,
                out=effective)
        np.maximum(effective, lo, out=effective)
        np.minimum(effective, hi, out=effective)
        self._effective = effective
        return self.frequencies_hz

    @property
    def frequencies_hz(self) -> np.ndarray:
        """The frequencies (Hz) the oscillators run at in this block, a new array."""
        return self._effective * (self.fs / TWO_PI)

    @property
    def rates_hz_per_s(self) -> np.ndarray:
        """The loops' learnt rates of change of the frequencies (Hz/s), a new array."""
        return self._rate * (self.fs ** 2 / TWO_PI)

    @property
    def estimates_hz(self) -> np.ndarray:
        """The loops' frequency estimates (Hz, the integrators), a new array."""
        return self._omega * (self.fs / TWO_PI)


def acquisition_frequencies(nominal_hz: Sequence[float] | np.ndarray, range_hz: float,
                            sample_rate_hz: float, line_frequencies_hz: np.ndarray,
                            line_strengths: np.ndarray) -> np.ndarray:
    """Where each tone should start: the strongest disturbance line within its bounds.

    The phase detector pulls a tone in only from about the canceller's own bandwidth
    (a 0.4 Hz offset at mu 0.0009 is never acquired), so a tone starts at the strongest
    line (largest ``line_strengths``) that lies within its :func:`tracking_bounds_hz`
    and only fine-tracks from there.

    Args:
        nominal_hz: (T,) the tones' nominal frequencies (Hz).
        range_hz: tracking range (Hz).
        sample_rate_hz: loop rate fs (Hz).
        line_frequencies_hz: (L,) the disturbance lines' frequencies (Hz).
        line_strengths: (L,) their strengths (any unit, larger is stronger).

    Returns:
        (T,) the start frequencies (Hz), NaN for a tone with no line within its bounds.
    """
    lower, upper = tracking_bounds_hz(nominal_hz, range_hz, sample_rate_hz)
    f = np.asarray(line_frequencies_hz, dtype=float).reshape(-1)
    s = np.asarray(line_strengths, dtype=float).reshape(-1)
    inside = (f[None, :] >= lower[:, None]) & (f[None, :] <= upper[:, None])   # (T, L)
    score = np.where(inside, s[None, :], -np.inf)
    out = np.full(lower.size, np.nan)
    if f.size:
        best = np.argmax(score, axis=1)
        found = np.isfinite(score[np.arange(lower.size), best])
        out[found] = f[best[found]]
    return out


ACQUISITION_RECORD_S = 1.0
"""Error record (s) the tones are acquired from when adaptation starts: long enough for a
line's frequency to a few hundredths of a hertz, short enough that a drifting line (0.3 Hz/s
in ``drift``) moves little over it."""
ACQUISITION_LINE_FACTOR = 100.0
"""A peak counts as a line when its power exceeds this times the record's median bin."""
ACQUISITION_GRID_HZ = 0.1


def strongest_lines_hz(record: np.ndarray, sample_rate_hz: float, lower_hz: np.ndarray,
                       upper_hz: np.ndarray) -> np.ndarray:
    """The frequency (Hz) of the strongest line within each ``[lower, upper]`` of a record.

    The Hann-windowed DTFT power of the (N, C) record (channels summed) on a
    :data:`ACQUISITION_GRID_HZ` grid over each interval, refined to its maximum by a
    bounded search; a maximum below :data:`ACQUISITION_LINE_FACTOR` times the median power
    of the record's FFT bins is no line (NaN).

    Args:
        record: (N, C) error samples (m/s^2), oldest first.
        sample_rate_hz: fs (Hz).
        lower_hz: (T,) the intervals' lower ends (Hz).
        upper_hz: (T,) their upper ends (Hz).

    Returns:
        (T,) line frequencies (Hz), NaN where there is none.
    """
    from scipy.optimize import minimize_scalar

    x = np.asarray(record, dtype=float)
    x = (x - x.mean(axis=0)) * np.hanning(x.shape[0])[:, None]
    n = np.arange(x.shape[0])
    floor = float(np.median(np.sum(np.abs(np.fft.rfft(x, axis=0)) ** 2, axis=1)))

    def power(f: np.ndarray) -> np.ndarray:
        kernel = np.exp(-2j * np.pi * np.outer(np.atleast_1d(f), n) / sample_rate_hz)
        return np.sum(np.abs(kernel @ x) ** 2, axis=1)

    out = np.full(np.size(lower_hz), np.nan)
    for t, (lo, hi) in enumerate(zip(np.atleast_1d(lower_hz), np.atleast_1d(upper_hz),
                                     strict=True)):
        grid = np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / ACQUISITION_GRID_HZ)) + 1))
        p = power(grid)
        best = int(np.argmax(p))
        fit = minimize_scalar(lambda f: -power(f)[0], method="bounded", bounds=(
            grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]),
            options={"xatol": 1e-4})
        if -fit.fun > ACQUISITION_LINE_FACTOR * floor:
            out[t] = float(fit.x)
    return out
