"""Adaptive Notch Canceller (paper eqs. 6-10), vectorized over tones x channels.

For every tone ``t`` (frequency ``f_t``) and channel ``i`` the canceller holds one complex
weight ``W[t, i] = a - j b`` (N) and drives

    u_n[i] = g_n * sum_t Re{W[t, i] e^{j phi_t,n}} = g_n * sum_t (a cos phi + b sin phi)

where ``phi_t`` (rad) is a wrapped phase accumulator advancing by ``2 pi f_t / fs`` per sample
and ``g_n`` the output gain (0..1, ramped for bumpless enable/disable). The weights and the law
that adapts them (the generalised paper update, the type-2 update of moving tones, the update
low-pass, anti-windup) are :class:`~hexapod_vibration.core.control.notch_weights.NotchWeights`;
this module adds the oscillators, the output and the changes of the tone set (tones removed
fade out; moved tones keep their phase).
Timing (docs/architecture.md): the command returned for sample ``n`` is held over
``[n/fs, (n+1)/fs)`` and first seen in the error of sample ``n+1``.

Implementation: ``e^{j phi_t}`` comes from a
:class:`~hexapod_vibration.core.control.phasor.PhasorBank` (one complex multiply per tone
and sample, exactly re-synchronised to the phase grid).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.control.notch_weights import NotchWeights, validate_coefficients
from hexapod_vibration.core.control.phasor import TWO_PI, PhasorBank

SAME_FREQUENCY_TOL_HZ = 1e-9
DEFAULT_RAMP_SAMPLES = 50
FADE_S = 1.0
"""The output's fade-out when control is switched off (s), along :func:`smooth_fade_gain`.

The fade puts back the disturbance the canceller cancelled, a line tens of dB above the
bands beside it, so the spectrum of its envelope must stay below them: a kinked envelope
(linear) spreads the line as 1/df^2, this one keeps it within +-3/FADE_S Hz and 58 dB down
beyond. Measured on the core loop against the uncontrolled twin, the converged canceller
of ``mismatch_tracking`` with the shaker at 41.0 Hz faded out at 32 s, worst 10 s window
of the 44.7-56.2 Hz third octave: linear over 0.25 s +22.9 dB; raised cosine over 0.5 / 1
/ 2 s +11.9 / +2.9 / +1.2 dB; this curve over 0.5 s +15.4 dB (its main lobe reaches the band
3.7 Hz away), over 1 s and 2 s no rise over the run without the fade (+1.06 dB). The
weights are frozen meanwhile: nothing runs away."""
_BLACKMAN = (0.42, 0.5, 0.08)
"""Coefficients of the Blackman window, the slope of :func:`smooth_fade_gain`."""


def smooth_fade_gain(progress: float) -> float:
    """Gain (0..1) at ``progress`` (0..1) of a ramp whose slope is a Blackman window.

    No kink at either end (zero slope and curvature): over a ramp of T s the envelope
    spreads a tone over +-3/T Hz, its sidelobes 58 dB down and falling as 1/df^4 where a
    linear ramp's fall as 1/df^2.
    """
    x = min(max(float(progress), 0.0), 1.0)
    a0, a1, a2 = _BLACKMAN
    return (a0 * x - a1 * math.sin(TWO_PI * x) / TWO_PI
            + a2 * math.sin(2.0 * TWO_PI * x) / (2.0 * TWO_PI)) / a0


def smooth_fade_progress(gain: float) -> float:
    """The progress (0..1) at which :func:`smooth_fade_gain` reaches ``gain`` (bisection)."""
    lo, hi = 0.0, 1.0
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if smooth_fade_gain(mid) < gain else (lo, mid)
    return 0.5 * (lo + hi)


def validate_frequencies(
    freqs_hz: Sequence[float] | np.ndarray, sample_rate_hz: float
) -> np.ndarray:
    """Return tone frequencies (Hz) as a float array or raise ValueError.

    Args:
        freqs_hz: tone frequencies (Hz); may be empty.
        sample_rate_hz: loop sample rate (Hz).

    Returns:
        1-D float array of the frequencies, in the given order.
    """
    f = np.asarray(freqs_hz, dtype=float).reshape(-1)
    if not np.all(np.isfinite(f)):
        raise ValueError(f"tone frequencies must be finite, got {f.tolist()}")
    nyquist = 0.5 * sample_rate_hz
    bad = f[(f <= 0.0) | (f >= nyquist)]
    if bad.size:
        raise ValueError(
            f"tone frequencies must be in (0, {nyquist:g}) Hz (fs/2), got {bad.tolist()}"
        )
    if f.size > 1:
        sorted_f = np.sort(f)
        if np.any(np.diff(sorted_f) <= SAME_FREQUENCY_TOL_HZ):
            raise ValueError(f"duplicate tone frequencies in {f.tolist()}")
    return f


def _validate_ramp(ramp_samples: int) -> int:
    ramp = int(ramp_samples)
    if ramp != ramp_samples or ramp < 0:
        raise ValueError(f"ramp_samples must be an integer >= 0, got {ramp_samples!r}")
    return ramp


class _FadingTones:
    """Tones removed from the canceller, faded out linearly so the output never jumps."""

    def __init__(self, n_channels: int) -> None:
        self._c = n_channels
        self.clear()

    def clear(self) -> None:
        """Drop all fading tones."""
        self.w = np.zeros((0, self._c), dtype=complex)
        self.phi = np.zeros(0)
        self.dphi = np.zeros(0)
        self.gain = np.zeros(0)
        self.step_size = np.zeros(0)
        self.active = False
        self._alloc()

    def _alloc(self) -> None:
        self._rot = np.zeros(self.phi.size, dtype=complex)
        self._rot_re, self._rot_im = self._rot.real, self._rot.imag
        self._contrib = np.zeros(self._c, dtype=complex)
        self._contrib_re = self._contrib.real

    def add(self, w: np.ndarray, phi: np.ndarray, dphi: np.ndarray, ramp: int) -> None:
        """Start fading tones with weights ``w`` (K, C), phases and increments (rad)."""
        if ramp == 0 or w.shape[0] == 0:
            return
        self.w = np.concatenate([self.w, w])
        self.phi = np.concatenate([self.phi, phi])
        self.dphi = np.concatenate([self.dphi, dphi])
        self.gain = np.concatenate([self.gain, np.ones(w.shape[0])])
        self.step_size = np.concatenate([self.step_size, np.full(w.shape[0], 1.0 / ramp)])
        self.active = True
        self._alloc()

    def advance(self, samples: int) -> None:
        """Skip ``samples`` samples: the same state as that many :meth:`accumulate` calls."""
        if self.phi.size == 0:
            return
        self.gain -= samples * self.step_size
        np.maximum(self.gain, 0.0, out=self.gain)
        self.phi += samples * self.dphi
        np.remainder(self.phi, TWO_PI, out=self.phi)
        if not np.any(self.gain):
            self.clear()

    def accumulate(self, out: np.ndarray) -> None:
        """Add this sample's faded output (N) to ``out`` (C,) and advance one sample."""
        if self.phi.size == 0:
            return
        self.gain -= self.step_size
        np.maximum(self.gain, 0.0, out=self.gain)
        np.cos(self.phi, out=self._rot_re)
        np.sin(self.phi, out=self._rot_im)
        np.multiply(self._rot_re, self.gain, out=self._rot_re)
        np.multiply(self._rot_im, self.gain, out=self._rot_im)
        np.matmul(self._rot, self.w, out=self._contrib)
        np.add(out, self._contrib_re, out=out)
        self.phi += self.dphi
        np.remainder(self.phi, TWO_PI, out=self.phi)
        if not np.any(self.gain):
            self.clear()


class AdaptiveNotchCanceller(NotchWeights):
    """Multichannel, multi-tone Adaptive Notch Canceller (paper eqs. 6-10, generalised).

    Args:
        n_channels: number of channels C (6 struts).
        tone_frequencies_hz: tone frequencies f_t (Hz), each in (0, fs/2), no duplicates.
        sample_rate_hz: loop sample rate fs (Hz).
        mu: adaptation rate (dimensionless with a normalised P; m/s^2 -> N scaling for P=I).
        coefficients: complex (T, C, C) adaptation matrices P_t (or (T, C) diagonals);
            None gives the paper's raw ``P = I``. Diagonal P uses the O(T*C) fast path.
    """

    def __init__(
        self,
        n_channels: int,
        tone_frequencies_hz: Sequence[float] | np.ndarray,
        sample_rate_hz: float,
        mu: float,
        coefficients: np.ndarray | None = None,
    ) -> None:
        """Validate the arguments (ValueError) and allocate the per-sample buffers."""
        if int(n_channels) != n_channels or n_channels < 1:
            raise ValueError(f"n_channels must be a positive integer, got {n_channels!r}")
        fs = float(sample_rate_hz)
        if not np.isfinite(fs) or fs <= 0.0:
            raise ValueError(f"sample_rate_hz must be finite and > 0, got {sample_rate_hz!r}")
        freqs = validate_frequencies(tone_frequencies_hz, fs)
        super().__init__(int(n_channels), fs, mu)
        p_full = validate_coefficients(coefficients, freqs.size, self._c)
        self._enabled = True
        self._frozen = False
        self._gain = 1.0
        self._target = 1.0
        self._gain_step = 0.0
        self._smooth = False
        self._progress = 1.0
        self._fading = _FadingTones(self._c)
        self._u = np.zeros(self._c)
        self._install(freqs, np.zeros((freqs.size, self._c), dtype=complex),
                      np.zeros(freqs.size), p_full, np.ones(freqs.size, dtype=bool),
                      np.zeros((freqs.size, self._c), dtype=complex), np.zeros(freqs.size))

    # ------------------------------------------------------------------ state management
    def _install(self, freqs: np.ndarray, w: np.ndarray, phi: np.ndarray,
                 p_full: np.ndarray, adapting: np.ndarray, z: np.ndarray,
                 ratio: np.ndarray) -> None:
        """Replace the tone set and (re)allocate every per-sample buffer."""
        self._freqs = freqs.copy()
        self._dphi = TWO_PI * freqs / self._fs
        self._osc = PhasorBank(self._dphi, phi)
        self._z_r = self._osc.z.view(float)                 # (2T,) cos, sin, cos, ...
        self._install_weights(w, p_full, adapting, z, ratio, self._osc.z)

    # ------------------------------------------------------------------ hot path
    def step(self, error: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Adapt on the error of sample n and return the command of sample n.

        Args:
            error: e_n, (C,) accelerations (m/s^2) of sample n, DC removed.
            out: optional (C,) float array to write the command into (no allocation).

        Returns:
            u_n, (C,) command forces (N) for sample n (``out`` if given, else a new array).
        """
        e = np.asarray(error, dtype=float)
        if e.shape != (self._c,):
            raise ValueError(f"error must have shape ({self._c},), got {e.shape}")
        if not math.isfinite(sum(e.tolist())):         # a NaN would poison the weights
            raise ValueError(f"error must be finite, got {e.tolist()}")
        if self._enabled and not self._frozen and self._mu > 0.0:
            self._adapt(e)
            if self._weight_limit is not None:
                self.limit_weights(self._weight_limit)
        if self._gain != self._target:
            self._move_gain(1)
        np.dot(self._v_r, self._z_r, out=self._u)          # sum_t a cos phi + b sin phi
        if self._fading.active:
            self._fading.accumulate(self._u)
        if self._gain != 1.0:
            self._u *= self._gain
        self._osc.rotate()
        if out is None:
            return self._u.copy()
        out[...] = self._u
        return out

    def advance(self, samples: int) -> None:
        """Skip ``samples`` samples whose error is unknown (missing messages).

        Phases, the enable ramp and fading tones move on exactly as ``samples`` calls of
        :meth:`step` with a zero error would move them, at O(1) cost; weights are unchanged.
        """
        samples = int(samples)
        if samples < 0:
            raise ValueError(f"samples must be >= 0, got {samples}")
        self._move_gain(samples)
        self._fading.advance(samples)
        self._osc.advance(samples)

    def gains_ahead(self, samples: int) -> np.ndarray:
        """The output gain of each of the next ``samples`` :meth:`step` calls (the ramp ahead).

        Entry k is the gain after k + 1 moves of the ramp, as :meth:`step` applies it.
        """
        moves = np.arange(1, int(samples) + 1)
        target, gain = self._target, self._gain
        if gain == target:
            return np.full(moves.size, gain)
        step = moves * self._gain_step
        if self._smooth:
            progress = self._progress
            ahead = (np.minimum(target, progress + step) if progress < target
                     else np.maximum(target, progress - step))
            return np.array([target if p == target else smooth_fade_gain(p) for p in ahead])
        if self._gain_step <= 0.0:
            return np.full(moves.size, target)
        return (np.minimum(target, gain + step) if gain < target
                else np.maximum(target, gain - step))

    def _move_gain(self, samples: int) -> None:
        """``samples`` samples of the ramp: linear in the gain, or along the smooth curve."""
        target = self._target
        if self._smooth:
            step = samples * self._gain_step
            self._progress = (min(target, self._progress + step) if self._progress < target
                              else max(target, self._progress - step))
            self._gain = (target if self._progress == target
                          else smooth_fade_gain(self._progress))
        elif self._gain_step <= 0.0 or samples * self._gain_step >= abs(target - self._gain):
            self._gain = target if samples else self._gain
        else:
            self._gain += math.copysign(samples * self._gain_step, target - self._gain)

    # ------------------------------------------------------------------ configuration
    def set_tone_frequencies(
        self,
        freqs_hz: Sequence[float] | np.ndarray,
        coefficients: np.ndarray | None = None,
        ramp_samples: int = DEFAULT_RAMP_SAMPLES,
    ) -> None:
        """Change the tone set without an output jump.

        Tones whose frequency is unchanged (within 1e-9 Hz) keep weight, phase, coefficient
        and adapting flag. New tones start with W = 0 and phase 0; they adapt only if
        ``coefficients`` is given. If given, ``coefficients`` ((T, C, C) or (T, C)) sets P
        for every tone of the new set. Removed tones fade out linearly over
        ``ramp_samples`` (frozen), so the command never steps.

        Raises:
            ValueError: bad frequencies, coefficients or ramp; the object is unchanged.
        """
        freqs = validate_frequencies(freqs_hz, self._fs)
        ramp = _validate_ramp(ramp_samples)
        given = None if coefficients is None else validate_coefficients(
            coefficients, freqs.size, self._c)
        t_new = freqs.size
        w = np.zeros((t_new, self._c), dtype=complex)
        phi = np.zeros(t_new)
        p_full = np.zeros((t_new, self._c, self._c), dtype=complex)
        adapting = np.zeros(t_new, dtype=bool)
        z = np.zeros((t_new, self._c), dtype=complex)
        ratio = np.full(t_new, self._integral_base)
        kept_old = np.zeros(self._freqs.size, dtype=bool)
        w_old, phi_old, z_old = self.weights, self.phases_rad, self.weight_rates
        for k, f in enumerate(freqs):
            match = np.flatnonzero(np.abs(self._freqs - f) <= SAME_FREQUENCY_TOL_HZ)
            if match.size:
                old = match[0]
                kept_old[old] = True
                w[k], phi[k], z[k] = w_old[old], phi_old[old], z_old[old]
                p_full[k], adapting[k] = self._p_full[old], self._adapting[old]
                ratio[k] = self._ratio[old]
        if given is not None:
            p_full, adapting[:] = given, True
        gone = ~kept_old
        self._fading.add(w_old[gone], phi_old[gone], self._dphi[gone], ramp)
        self._install(freqs, w, phi, p_full, adapting, z, ratio)

    def retune(self, freqs_hz: np.ndarray) -> None:
        """Move every tone to ``freqs_hz`` (Hz, (T,)) from the next sample on.

        The oscillators' phases are continuous (no phase step) and weights, coefficients
        and adapting flags are kept: this is how tracked tones follow their estimates, once
        per block of samples. The tone set itself (its size and order) is unchanged.

        Raises:
            ValueError: wrong shape, or a frequency not in (0, fs/2); nothing changed.
        """
        f = np.asarray(freqs_hz, dtype=float)
        if f.shape != self._freqs.shape:
            raise ValueError(f"retune needs {self._freqs.size} frequencies, got {f.shape}")
        if f.size and not (f.min() > 0.0 and f.max() < 0.5 * self._fs):
            raise ValueError(f"tone frequencies must be in (0, {0.5 * self._fs:g}) Hz, "
                             f"got {f.tolist()}")
        self._freqs[...] = f
        np.multiply(f, TWO_PI / self._fs, out=self._dphi)
        self._osc.retune(self._dphi)

    def reset_weights(self, ramp_samples: int = DEFAULT_RAMP_SAMPLES) -> None:
        """Set every weight to 0; the present output fades out over ``ramp_samples``."""
        ramp = _validate_ramp(ramp_samples)
        self._fading.add(self.weights, self.phases_rad, self._dphi.copy(), ramp)
        self._v[:] = 0.0
        self._stop_rates()

    def set_enabled(self, flag: bool, ramp_samples: int = DEFAULT_RAMP_SAMPLES,
                    smooth: bool = False) -> None:
        """Enable/disable the output with a gain ramp 0 <-> 1 over ``ramp_samples``.

        Linear, or with ``smooth`` along :func:`smooth_fade_gain` from the present gain (a
        fade-out that must not splatter the tone it stops cancelling over the bands beside
        it). While disabled adaptation is frozen and the weights are kept, so re-enabling
        resumes from the last weights.
        """
        ramp = _validate_ramp(ramp_samples)
        if not flag:
            self._stop_rates()
        self._enabled = bool(flag)
        self._target = 1.0 if self._enabled else 0.0
        self._gain_step = 1.0 / ramp if ramp > 0 else 0.0
        self._smooth = bool(smooth) and ramp > 0
        if self._smooth:
            self._progress = smooth_fade_progress(self._gain)

    def set_frozen(self, flag: bool) -> None:
        """Freeze (True) or resume (False) adaptation; the output keeps running.

        Freezing clears the weights' rate of change (type-2 update): frozen weights hold.
        """
        if flag:
            self._stop_rates()
        self._frozen = bool(flag)

    # ------------------------------------------------------------------ read-only views
    @property
    def tone_frequencies_hz(self) -> np.ndarray:
        """Tone frequencies (Hz), a copy."""
        return self._freqs.copy()

    @property
    def phases_rad(self) -> np.ndarray:
        """Phase accumulators phi_t (rad, in [0, 2 pi)) of the next sample, a copy."""
        return self._osc.phases_rad

    @property
    def phase_steps_rad(self) -> np.ndarray:
        """The oscillators' phase increments dphi_t (rad per sample), a copy."""
        return self._osc.dphi_rad

    @property
    def enabled(self) -> bool:
        """Whether the output is (ramping) on."""
        return self._enabled

    @property
    def frozen(self) -> bool:
        """Whether adaptation is frozen by :meth:`set_frozen`."""
        return self._frozen

    @property
    def output_gain(self) -> float:
        """Present output gain in [0, 1]."""
        return self._gain

    @property
    def n_channels(self) -> int:
        """Number of channels C."""
        return self._c

    @property
    def n_tones(self) -> int:
        """Number of tones T (no copy of the frequencies)."""
        return self._freqs.size

    @property
    def sample_rate_hz(self) -> float:
        """Loop sample rate (Hz)."""
        return self._fs
