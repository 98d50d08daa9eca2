"""The adaptive weights of the notch canceller and the law that adapts them.

For every tone ``t`` and channel ``i`` one complex weight ``W[t, i] = a - j b`` (N), adapted
with the generalised paper update (eqs. 8-9, ``P = I`` is the paper as printed)

    W_t += mu * P_t @ (e_n * e^{-j phi_t,n})

with ``e_n`` the (DC-blocked) accelerations (m/s^2) of sample ``n`` and ``e^{j phi_t,n}`` the
tone's oscillator (:mod:`~hexapod_vibration.core.control.notch`). A diagonal ``P`` takes an
O(T*C) path (the paper's decentralised SISO loops); a full ``P`` costs O(T*C*C).

Optionally (:meth:`NotchWeights.set_integral_ratio`, moving tones) the update is of type 2:
a second state ``Z_t``, the weights' rate of change (N per sample), integrates the same
correction and the weights move on by it every sample,

    Z_t += kappa_t * mu P_t (e_n e^{-j phi_t,n}),   W_t += mu P_t (e_n e^{-j phi_t,n}) + Z_t,

``kappa_t = ratio_t * mu``. A disturbance whose phasor changes at a steady rate (a tone
sweeping through the plant's and the disturbance path's response, its amplitude growing
with speed^2) then leaves no residual; the first-order update leaves ``1/mu`` samples of
that change. With the normalised P (M = I) the averaged loop of the residual is
``s^2 + mu s + kappa mu`` (per sample): damping ``zeta = 1 / (2 sqrt(ratio))``.
Optionally (:meth:`NotchWeights.set_update_lowpass`) each tone's correction
``mu P_t e_n e^{-j phi_t,n}`` (a baseband signal) passes a first-order low-pass of corner
``f_c`` before it reaches the weights (and the rate integrator). At the tone nothing changes
(unit gain at DC: the same notch, the same converged weights); away from it the canceller's
gain falls by ``f_c / |f - f_t|`` more (its tails), so a tone no longer lifts a lightly damped
loop mode tens of hertz away (Table 1 at mu 0.002: the 18.7 Hz mode's predicted rise
+1.9 dB -> +0.3 dB with f_c = 10 Hz), and the weights' 2 f_t ripple is smoothed too. The price is
phase lag near the tone, ``atan(df / f_c)`` at an offset df: negligible at the weight
loop's bandwidth (``~mu fs / 2 pi``, 0.3 Hz at mu 0.002), and in the Nyquist bound and the
predicted sensitivity (:func:`update_lowpass_response`). After every update the weights can
be clamped to the actuators' rating (anti-windup, :meth:`NotchWeights.limit_weights`).

Implementation: the weights are stored conjugated and transposed,
``V[i, t] = conj(W[t, i]) = a + j b``, so that the output ``sum_t a cos phi + b sin phi`` is
one real matrix-vector product of the float views of ``V`` and ``e^{j phi}``, and the update
``V += conj(mu P) e e^{+j phi}`` needs no conjugation per sample. Every per-sample operation
writes into buffers allocated when the tone set changes (:meth:`NotchWeights._install_weights`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.control.weight_ceiling import WeightCeiling


def validate_mu(mu: float) -> float:
    """Return ``mu`` as float or raise ValueError if it is not finite and >= 0."""
    try:
        value = float(mu)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"mu must be a real number, got {mu!r}") from exc
    if not np.isfinite(value) or value < 0.0:
        raise ValueError(f"mu must be finite and >= 0, got {value}")
    return value


def validate_coefficients(
    coefficients: np.ndarray | None, n_tones: int, n_channels: int
) -> np.ndarray:
    """Return adaptation coefficients as a complex (T, C, C) array or raise ValueError.

    Args:
        coefficients: complex (T, C, C) matrices P_t, or (T, C) diagonals, or None for
            the paper's raw ``P = I``.
        n_tones: number of tones T.
        n_channels: number of channels C.

    Returns:
        A new complex (T, C, C) array.
    """
    if coefficients is None:
        return np.broadcast_to(np.eye(n_channels, dtype=complex),
                               (n_tones, n_channels, n_channels)).copy()
    p = np.array(coefficients, dtype=complex)
    if p.shape == (n_tones, n_channels):
        p = p[:, :, None] * np.eye(n_channels)
    if p.shape != (n_tones, n_channels, n_channels):
        raise ValueError(
            f"coefficients must have shape (T, C, C) = ({n_tones}, {n_channels}, {n_channels})"
            f" or (T, C) for diagonal P, got {p.shape}"
        )
    if not np.all(np.isfinite(p)):
        raise ValueError("coefficients must be finite")
    return p


def _diagonal_or_none(p_full: np.ndarray) -> np.ndarray | None:
    """Return the (T, C) diagonals if every P_t is diagonal, else None."""
    diag = np.diagonal(p_full, axis1=1, axis2=2)
    off = p_full - diag[:, :, None] * np.eye(p_full.shape[1])
    return diag.copy() if not np.any(off) else None


def validate_update_lowpass(corner_hz: float, sample_rate_hz: float) -> float:
    """The update low-pass corner (Hz): 0 (off) or in (0, fs/2); ValueError otherwise."""
    value = float(corner_hz)
    if not math.isfinite(value) or value < 0.0 or value >= 0.5 * sample_rate_hz:
        raise ValueError(f"update_lowpass_hz must be 0 (off) or in (0, "
                         f"{0.5 * sample_rate_hz:g}) Hz, got {corner_hz!r}")
    return value


def update_lowpass_pole(corner_hz: float, sample_rate_hz: float) -> float:
    """Pole ``a = exp(-2 pi f_c / fs)`` of the update low-pass ``(1 - a) / (1 - a z^-1)``.

    0 for ``corner_hz = 0``: no filter (the paper's update).
    """
    return math.exp(-2.0 * math.pi * corner_hz / sample_rate_hz) if corner_hz > 0.0 else 0.0


def update_lowpass_response(corner_hz: float, sample_rate_hz: float,
                            baseband_z: np.ndarray) -> np.ndarray:
    """The update low-pass at baseband ``zeta = z e^{-j w_t}`` (1 everywhere when off).

    The correction of tone t is demodulated by ``e^{-j phi_t}``, so a frequency z of the
    error reaches the filter at ``z e^{-j w_t}`` (and ``z e^{+j w_t}`` for the conjugate
    branch); the filter is ``L(zeta) = (1 - a) zeta / (zeta - a)``, with no delay (the
    filtered correction is applied in the same sample, as :meth:`NotchWeights._adapt`
    does).
    """
    a = update_lowpass_pole(corner_hz, sample_rate_hz)
    zeta = np.asarray(baseband_z, dtype=complex)
    if a == 0.0:
        return np.ones_like(zeta)
    return (1.0 - a) * zeta / (zeta - a)


class NotchWeights:
    """The weights W (T, C) of T tones x C channels and their adaptation law (see module).

    The canceller (:class:`~hexapod_vibration.core.control.notch.AdaptiveNotchCanceller`)
    is these weights with their oscillators and an output; the tone set is installed by it
    (:meth:`_install_weights`), with the oscillators' phasors the update multiplies by.

    Args:
        n_channels: number of channels C.
        sample_rate_hz: loop sample rate fs (Hz).
        mu: adaptation rate (dimensionless with a normalised P; m/s^2 -> N scaling for P=I).
    """

    def __init__(self, n_channels: int, sample_rate_hz: float, mu: float) -> None:
        """Check ``mu`` (ValueError); no tone until :meth:`_install_weights`."""
        self._c = int(n_channels)
        self._fs = float(sample_rate_hz)
        self._mu = validate_mu(mu)
        self._weight_limit: float | None = None
        self._integral_base = 0.0
        self._lowpass_hz = 0.0
        self._lowpass_pole = 0.0
        self._ceiling = WeightCeiling()
        self._adapted_scratch: np.ndarray | None = None
        self.clamped_samples = 0

    def _install_weights(self, w: np.ndarray, p_full: np.ndarray, adapting: np.ndarray,
                         z: np.ndarray, ratio: np.ndarray, phasors: np.ndarray) -> None:
        """A new tone set: weights (T, C), P, adapting flags, rates (T, C), ratios (T,).

        ``phasors``: the oscillators' ``e^{j phi_t}`` (T,), rotated in place each sample.
        Every per-sample buffer is (re)allocated.
        """
        t = phasors.size
        self._z_row_r = phasors.view(float).reshape(1, 2 * t)    # cos, sin, cos, ...
        self._z_stack = phasors[:, None, None]              # (T, 1, 1)
        self._v = np.ascontiguousarray(np.conj(w).T, dtype=complex)   # V = W^H, (C, T)
        self._v_r = self._v.view(float)                     # (C, 2T) a, b, a, b, ...
        self._y = np.zeros((self._c, t), dtype=complex)     # update of V
        self._y_r = self._y.view(float)
        self._y_stack = self._y.T[:, None, :]               # (T, 1, C) view of y
        self._m = np.zeros((self._c, t), dtype=complex)     # conj(mu P) e (full P)
        self._m_flat = self._m.view(float).reshape(-1)
        self._m_stack = self._m.T[:, None, :]
        self._zv = np.ascontiguousarray(np.conj(z).T, dtype=complex)  # conj(Z)^T, (C, T)
        self._zy = np.zeros((self._c, t), dtype=complex)    # kappa * update of V
        self._lp = np.zeros((self._c, t), dtype=complex)    # low-passed update of V
        self._ratio = np.asarray(ratio, dtype=float).copy()
        self._adapting = adapting.astype(bool).copy()
        self._set_p(p_full)

    def _stop_rates(self) -> None:
        """The weights hold: no rate of change to resume with, no filtered correction to come."""
        self._zv[:] = 0.0
        self._lp[:] = 0.0

    def _set_p(self, p_full: np.ndarray) -> None:
        self._p_full = p_full.copy()
        self._p_diag = _diagonal_or_none(self._p_full)
        self._update_rate()

    def _update_rate(self) -> None:
        """Rate-scaled, conjugated coefficients in the layouts :meth:`_adapt` uses.

        Diagonal P: ``Q[i, t] = mu_t conj(P_t[i, i])`` (C, T) complex. Full P: the real
        (C*T*2, C) stack of ``Re, Im`` of ``mu_t conj(P_t[i, j])`` over rows (i, t), so
        that its product with the real error is the complex (C, T) array
        ``sum_j mu_t conj(P_t[i, j]) e_j`` in memory. ``mu_t = mu`` for adapting tones, else 0.
        """
        # the update low-pass's input gain (1 - a) is folded into the rates (one call less
        # per sample); _adapt then filters the already-scaled correction
        rate = self._mu * self._adapting * (1.0 - self._lowpass_pole)
        # kappa_t for every channel, complex (C, T): same shape and dtype as the update
        self._kappa = np.ascontiguousarray(np.broadcast_to(
            (self._ratio * self._mu).astype(complex), self._y.shape))
        self._integral = bool(np.any(self._ratio > 0.0))
        q = np.conj(rate[:, None, None] * self._p_full).transpose(1, 0, 2)    # (C, T, C)
        if self._p_diag is not None:
            self._q = np.ascontiguousarray(np.diagonal(q, axis1=0, axis2=2).T)
            self._q_stack = None
        else:
            self._q = None
            self._q_stack = np.ascontiguousarray(
                np.stack([q.real, q.imag], axis=2).reshape(-1, self._c))

    def _adapt(self, e: np.ndarray) -> None:
        """V += conj(mu P) e e^{j phi} (i.e. W += mu P e e^{-j phi}), masked per tone.

        Three calls, all with ``out=``, same dtypes and no broadcasting ufunc (those
        allocate iterator buffers): diagonal P forms the outer product ``e e^{j phi}`` as
        a real (C, 1) x (1, 2T) matrix product into the float view of ``y`` and scales it
        by ``Q``; full P takes ``conj(mu P) e`` as one real matrix-vector product and
        multiplies it by ``e^{j phi_t}`` as T stacked 1 x 1 products.
        """
        if self._q is not None:
            np.dot(e[:, None], self._z_row_r, out=self._y_r)
            np.multiply(self._y, self._q, out=self._y)
        else:
            np.dot(self._q_stack, e, out=self._m_flat)
            np.matmul(self._z_stack, self._m_stack, out=self._y_stack)
        if self._lowpass_pole:              # y is (1 - a) x the correction already
            np.multiply(self._lp, self._lowpass_pole, out=self._lp)
            np.add(self._lp, self._y, out=self._y)
            np.copyto(self._lp, self._y)
        if self._integral:
            np.multiply(self._y, self._kappa, out=self._zy)
            np.add(self._zv, self._zy, out=self._zv)
            np.add(self._y, self._zv, out=self._y)
        np.add(self._v, self._y, out=self._v)

    def set_mu(self, mu: float) -> None:
        """Set the adaptation rate (>= 0, finite); raise ValueError and keep the old one."""
        self._mu = validate_mu(mu)
        self._update_rate()

    def set_coefficients(self, coefficients: np.ndarray | None) -> None:
        """Set P for every tone ((T, C, C) or (T, C) diagonal; None = raw P = I).

        Every tone adapts afterwards. Weights and phases are kept, so the output is
        continuous. Raises ValueError (object unchanged) on a bad shape or value.
        """
        p_full = validate_coefficients(coefficients, self._v.shape[1], self._c)
        self._adapting[:] = True
        self._set_p(p_full)

    def set_weights(self, weights: np.ndarray) -> None:
        """Overwrite the complex (T, C) weights (N); the output follows immediately."""
        self._v[...] = self._channel_major(weights, "weights")

    def _channel_major(self, values: np.ndarray, what: str) -> np.ndarray:
        """conj(X)^T (C, T) of a finite complex (T, C) array, the layout of the state."""
        x = np.array(values, dtype=complex)
        shape = (self._v.shape[1], self._c)
        if x.shape != shape or not np.all(np.isfinite(x)):
            raise ValueError(f"{what} must be finite with shape {shape}, got {x.shape}")
        return np.conj(x).T

    def limit_weights(self, limit_n: float) -> bool:
        """Anti-windup: each channel's weights clipped so that sum_t |W[t, i]| <= limit_n (N).

        The largest magnitudes are clipped at a common ceiling
        (:class:`~hexapod_vibration.core.control.weight_ceiling.WeightCeiling`), so the
        canceller never asks for more than ``limit_n``. Returns True if a weight was clipped.
        """
        over = self._ceiling.clip(self._v, limit_n)
        if over is None:
            return False
        if self._integral:
            self._zv[over] = 0.0         # anti-windup of the rate too
        self.clamped_samples += 1
        return True

    def set_integral_ratio(self, ratio: float | Sequence[float] | np.ndarray) -> None:
        """Type-2 update (see the module): ``kappa_t = ratio_t * mu`` (0: first order).

        ``ratio`` is one value (every tone, and tones added later) or one per tone (T,),
        finite and >= 0; ``1 / (4 zeta^2)`` gives damping ``zeta`` with the normalised P.
        Setting it keeps the weights' present rates of change (0 where the ratio is 0).

        Raises:
            ValueError: a bad shape or value; the object is unchanged.
        """
        r = np.asarray(ratio, dtype=float)
        t = self._v.shape[1]
        if r.ndim == 0:
            values, base = np.full(t, float(r)), float(r)
        elif r.shape == (t,):
            values, base = r.copy(), float(r.max(initial=0.0))
        else:
            raise ValueError(f"integral ratio must be one value or {t}, got shape {r.shape}")
        if not np.all(np.isfinite(values)) or np.any(values < 0.0):
            raise ValueError(f"integral ratio must be finite and >= 0, got {values.tolist()}")
        self._ratio, self._integral_base = values, base
        self._zv[:, values == 0.0] = 0.0
        self._update_rate()

    def set_update_lowpass(self, corner_hz: float) -> None:
        """Low-pass each tone's correction at ``corner_hz`` (Hz, see the module; 0: off).

        The filter starts from rest. Raises ValueError (object unchanged) unless
        ``corner_hz`` is 0 or in (0, fs/2).
        """
        self._lowpass_hz = validate_update_lowpass(corner_hz, self._fs)
        self._lowpass_pole = update_lowpass_pole(self._lowpass_hz, self._fs)
        self._lp[:] = 0.0
        self._update_rate()

    def set_weight_rates(self, rates: np.ndarray) -> None:
        """Overwrite the weights' rates of change Z (T, C) (N per sample, type-2 update)."""
        self._zv[...] = self._channel_major(rates, "rates")

    def set_weight_limit(self, limit_n: float | None) -> None:
        """Apply :meth:`limit_weights` after every adaptation step (None: no limit)."""
        if limit_n is not None and not (np.isfinite(limit_n) and limit_n > 0.0):
            raise ValueError(f"weight limit must be finite and > 0 N, got {limit_n!r}")
        self._weight_limit = None if limit_n is None else float(limit_n)

    @property
    def weights(self) -> np.ndarray:
        """Complex (T, C) weights W = a - j b (N), a copy."""
        return np.conj(self._v).T.copy()

    @property
    def weight_rates(self) -> np.ndarray:
        """Complex (T, C) rates of change Z of the weights (N per sample), a copy.

        Zero unless the type-2 update (:meth:`set_integral_ratio`) is on.
        """
        return np.conj(self._zv).T.copy()

    @property
    def integrating(self) -> bool:
        """True while some tone adapts with the type-2 update (a ratio > 0)."""
        return self._integral

    @property
    def adapted_weights(self) -> np.ndarray:
        """Complex (T, C) weights (N) with every correction so far applied in full.

        Without the update low-pass these are :attr:`weights`. With it, the corrections
        still inside the filter are added: the sum of the filter's inputs equals the sum of
        its outputs plus ``a / (1 - a)`` times its state (first order, unit DC gain), so the
        change of these over a block is the block's unfiltered correction, without the
        filter's lag (what a phase detector on the weights must see).
        """
        if not self._lowpass_pole:
            return self.weights
        return np.conj(self._adapted_h(np.empty_like(self._v))).T

    def add_adapted_weights_h(self, total: np.ndarray) -> None:
        """``total += conj(adapted_weights).T`` in place: no array allocated (1 kHz path).

        ``total`` is complex (C, T), the layout the canceller keeps its weights in
        (``V = W^H``); summed over samples and conjugated once, it gives the sum of
        :attr:`adapted_weights`, bit for bit.
        """
        if not self._lowpass_pole:
            np.add(total, self._v, out=total)
            return
        if self._adapted_scratch is None or self._adapted_scratch.shape != self._v.shape:
            self._adapted_scratch = np.empty_like(self._v)
        np.add(total, self._adapted_h(self._adapted_scratch), out=total)

    def _adapted_h(self, out: np.ndarray) -> np.ndarray:
        """``V + a / (1 - a) LP`` (the adapted weights, conjugated, (C, T)) into ``out``."""
        a = self._lowpass_pole
        np.multiply(self._lp, a / (1.0 - a), out=out)
        return np.add(out, self._v, out=out)

    @property
    def update_lowpass_hz(self) -> float:
        """Corner of the update low-pass (Hz; 0: the paper's update)."""
        return self._lowpass_hz

    @property
    def integral_ratio(self) -> np.ndarray:
        """Per-tone ratios ``kappa_t / mu`` of the type-2 update (T,), a copy."""
        return self._ratio.copy()

    @property
    def coefficients(self) -> np.ndarray:
        """Complex (T, C, C) adaptation matrices P_t, a copy."""
        return self._p_full.copy()

    @property
    def coefficients_view(self) -> np.ndarray:
        """The (T, C, C) matrices P_t themselves (read only; a new object whenever P changes)."""
        return self._p_full

    @property
    def is_diagonal(self) -> bool:
        """True when every P_t is diagonal (O(T*C) update path)."""
        return self._p_diag is not None

    @property
    def adapting(self) -> np.ndarray:
        """Per-tone adapting flags (T,), a copy."""
        return self._adapting.copy()

    @property
    def adapts(self) -> bool:
        """True when some tone adapts (its coefficient P is in force: given, or raw P = I)."""
        return bool(self._adapting.any())

    @property
    def mu(self) -> float:
        """Adaptation rate."""
        return self._mu
