"""Stability bounds, adaptation coefficients and tone-response identification.

Averaged weight dynamics (docs/architecture.md). With a real error
``e_n = Re{(G W + D) e^{j phi_n}}`` the update ``W += mu P e_n e^{-j phi_n}`` sees
``e_n e^{-j phi_n} = (G W + D)/2 + conj(G W + D) e^{-2 j phi_n}/2``. The second term averages
out over the double-frequency period, so on average

    W_{n+1} = W_n + (mu/2) P (G W_{n-d} + D) = W_n - mu M W_{n-d} + ...,   M = -(1/2) P G,

where ``d`` is the loop delay in samples beyond the one-sample command hold (0 for a plant
that is a pure gain with the one-sample hold; about the plant's group delay at the tone
minus one sample otherwise). The normalised choice ``P = -2 G^{-1}`` makes ``M = I`` and
``mu`` the per-sample convergence rate. These formulas hold for ``mu`` small enough that the
double-frequency term averages out (slow weights compared with the tone period).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.control.notch import TWO_PI, validate_frequencies
from hexapod_vibration.parameter_specs import ADAPTATION_MODES

MAX_CONDITION_NUMBER = 1e6


def paper_mu_bound(alpha: float, beta_rad: float) -> float:
    """Largest stable raw ``mu`` (P = 1) for a SISO plant ``H = alpha e^{j beta}``, eq. (18).

    The paper writes ``|1 + mu alpha e^{j beta}| < 1`` from a complex-signal derivation. With
    real signals the error's phasor enters the update only half (``e e^{-j phi}`` averages to
    ``(G W + D)/2``), so the averaged weight recursion is
    ``W_{n+1} = (1 + (mu/2) alpha e^{j beta}) W_n + ...``, stable iff
    ``1 + mu alpha cos(beta) + mu^2 alpha^2 / 4 < 1``, i.e. ``0 < mu < -4 cos(beta)/alpha``.

    Args:
        alpha: plant gain at the tone (m/s^2 per N), > 0.
        beta_rad: plant phase at the tone (rad), including the one-sample command hold.

    Returns:
        The bound (N per m/s^2 per sample); 0.0 when ``cos(beta) >= 0`` (no positive raw
        ``mu`` is stable: a positive-phase plant needs the sign flip of a coefficient).
    """
    if not np.isfinite(alpha) or alpha <= 0.0:
        raise ValueError(f"alpha must be finite and > 0, got {alpha}")
    c = float(np.cos(beta_rad))
    return -4.0 * c / alpha if c < 0.0 else 0.0


def _as_stack(m: np.ndarray) -> np.ndarray:
    """Return a complex (T, C, C) stack from a scalar, a (C, C) matrix or a (T, C, C) stack."""
    a = np.asarray(m, dtype=complex)
    if a.ndim == 0:
        return a.reshape(1, 1, 1)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[1] != a.shape[2]:
        raise ValueError(f"expected a square matrix or a (T, C, C) stack, got shape {a.shape}")
    return a


def weight_loop_eigenvalues(G: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``M = -(1/2) P G`` (M = I for the normalised P).

    Args:
        G: plant response(s), complex (C, C) or (T, C, C) (m/s^2 per N).
        P: adaptation coefficient(s), same shape as G (N per m/s^2).

    Returns:
        Complex eigenvalues, (C,) for (C, C) input or (T, C) for a stack.
    """
    g, p = _as_stack(G), _as_stack(P)
    if g.shape != p.shape:
        raise ValueError(f"G and P must have the same shape, got {g.shape} and {p.shape}")
    lam = np.linalg.eigvals(-0.5 * p @ g)
    return lam[0] if np.ndim(G) < 3 else lam


def _delay_int(delay_samples: float) -> int:
    if not np.isfinite(delay_samples) or delay_samples < 0.0:
        raise ValueError(f"delay_samples must be finite and >= 0, got {delay_samples}")
    return int(np.ceil(delay_samples - 1e-12))


def delayed_mode_mu_bound(lam: complex, delay_samples: float = 0.0) -> float:
    """Largest ``mu`` keeping ``W_{n+1} = W_n - mu lam W_{n-d}`` stable (closed form).

    The roots of ``z^{d+1} - z^d + s`` cross the unit circle at
    ``s = -2j sin(theta/2) e^{j (d + 1/2) theta}``; along the ray ``s = mu lam`` the first
    crossing is at ``mu = 2 sin((pi/2 - |arg lam|) / (2d + 1)) / |lam|`` (for real lam:
    ``2 sin(pi / (2 (2d + 1))) / lam``; for d = 0: ``2 Re(lam) / |lam|^2``).

    Args:
        lam: mode eigenvalue (complex).
        delay_samples: loop delay d (samples), rounded up to an integer.

    Returns:
        The bound, or 0.0 if ``Re(lam) <= 0`` (no positive mu is stable).
    """
    d = _delay_int(delay_samples)
    lam = complex(lam)
    if lam.real <= 0.0:
        return 0.0
    margin = 0.5 * np.pi - abs(np.angle(lam))
    return float(2.0 * np.sin(margin / (2 * d + 1)) / abs(lam))


def delayed_mode_radius(lam: complex, mu: float, delay_samples: float = 0.0) -> float:
    """Spectral radius (per sample) of ``W_{n+1} = W_n - mu lam W_{n-d}`` (numpy.roots)."""
    d = _delay_int(delay_samples)
    poly = np.zeros(d + 2, dtype=complex)
    poly[0], poly[1] = 1.0, -1.0
    poly[-1] += mu * complex(lam)
    return float(np.max(np.abs(np.roots(poly))))


def mu_bound(G: np.ndarray, P: np.ndarray, delay_samples: float = 0.0) -> float:
    """Largest stable ``mu`` of the averaged, delayed weight loop for every mode and tone.

    Args:
        G: plant response(s), complex (C, C) or (T, C, C).
        P: adaptation coefficient(s), same shape as G.
        delay_samples: loop delay d beyond the one-sample command hold (samples).

    Returns:
        The bound (exclusive), 0.0 if some eigenvalue of M has ``Re <= 0``.
    """
    lams = np.ravel(weight_loop_eigenvalues(G, P))
    if lams.size == 0:
        return float("inf")
    return min(delayed_mode_mu_bound(lam, delay_samples) for lam in lams)


def convergence_factor(G: np.ndarray, P: np.ndarray, mu: float,
                       delay_samples: float = 0.0) -> float:
    """Per-sample contraction factor of the slowest mode (spectral radius, < 1 if stable).

    Args:
        G: plant response(s), complex (C, C) or (T, C, C).
        P: adaptation coefficient(s), same shape as G.
        mu: adaptation rate.
        delay_samples: loop delay d beyond the one-sample command hold (samples).

    Returns:
        max over modes of the largest root modulus of ``z^{d+1} - z^d + mu lam``.
    """
    lams = np.ravel(weight_loop_eigenvalues(G, P))
    return max((delayed_mode_radius(lam, mu, delay_samples) for lam in lams), default=0.0)


def predicted_time_constant_s(G: np.ndarray, P: np.ndarray, mu: float, sample_rate_hz: float,
                              delay_samples: float = 0.0) -> float:
    """Time constant (s) of the slowest weight mode: ``-1 / (fs ln rho)``; inf if unstable."""
    rho = convergence_factor(G, P, mu, delay_samples)
    if rho >= 1.0:
        return float("inf")
    if rho <= 0.0:
        return 0.0
    return float(-1.0 / (sample_rate_hz * np.log(rho)))


def canceller_state_space(
    tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
    coefficients: np.ndarray, mu: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact LTI form (A, B, C, D) of the adapting canceller from error e (C,) to command u (C,).

    With the phase-rotated weights ``V_t,n = W_t,n e^{j phi_t,n}`` the canceller is time
    invariant: ``V_{n+1} = e^{j w_t} (V_n + mu P_t e_n)``, ``u_n = sum_t Re{V_t,n + mu P_t e_n}``
    (Widrow's adaptive notch). Real state ``[Re V; Im V]`` of size 2 T C.

    Args:
        tone_frequencies_hz: tones (Hz).
        sample_rate_hz: loop sample rate (Hz).
        coefficients: complex (T, C, C) adaptation matrices P_t.
        mu: adaptation rate.

    Returns:
        Real matrices A (2TC, 2TC), B (2TC, C), C (C, 2TC), D (C, C).
    """
    freqs = validate_frequencies(tone_frequencies_hz, sample_rate_hz)
    p = _as_stack(coefficients)
    t, c = p.shape[0], p.shape[1]
    if t != freqs.size:
        raise ValueError(f"{freqs.size} tones but {t} coefficient matrices")
    rot = np.kron(np.diag(np.exp(1j * TWO_PI * freqs / sample_rate_hz)), np.eye(c))
    p_stack = mu * p.reshape(t * c, c)
    a_c, b_c = rot, rot @ p_stack
    a = np.block([[a_c.real, -a_c.imag], [a_c.imag, a_c.real]])
    b = np.vstack([b_c.real, b_c.imag])
    s = np.tile(np.eye(c), (1, t))
    return a, b, np.hstack([s, np.zeros_like(s)]), p_stack.real.reshape(t, c, c).sum(axis=0)


def closed_loop_spectral_radius(
    plant: tuple[np.ndarray, np.ndarray, np.ndarray],
    tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
    coefficients: np.ndarray, mu: float,
) -> float:
    """Exact per-sample spectral radius of plant + adapting canceller (no averaging).

    Args:
        plant: discrete state space (A, B, C) at the loop rate with the one-sample command
            hold of docs/architecture.md: ``x_{n+1} = A x_n + B u_n``, ``e_n = C x_n + d_n``.
        tone_frequencies_hz: tones (Hz).
        sample_rate_hz: loop sample rate (Hz).
        coefficients: complex (T, C, C) adaptation matrices.
        mu: adaptation rate.

    Returns:
        Largest closed-loop eigenvalue modulus (< 1: stable; includes the plant's own poles).
    """
    a_p, b_p, c_p = (np.asarray(m, dtype=float) for m in plant)
    a_k, b_k, c_k, d_k = canceller_state_space(tone_frequencies_hz, sample_rate_hz,
                                               coefficients, mu)
    a_cl = np.block([[a_p + b_p @ d_k @ c_p, b_p @ c_k], [b_k @ c_p, a_k]])
    return float(np.max(np.abs(np.linalg.eigvals(a_cl))))


def exact_mu_bound(
    plant: tuple[np.ndarray, np.ndarray, np.ndarray],
    tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
    coefficients: np.ndarray, mu_max: float = 10.0, rtol: float = 1e-4,
) -> float:
    """Smallest ``mu`` in (0, mu_max] at which the exact closed loop loses stability.

    Scans a log grid from ``mu_max * 1e-6`` and bisects the first unstable interval, so
    every ``mu`` below the result is stable. Returns ``mu_max`` if all of the grid is stable,
    0.0 if even the smallest ``mu`` is unstable (e.g. an unstable plant or Re(M) < 0).

    Args:
        plant: discrete state space (A, B, C), see :func:`closed_loop_spectral_radius`.
        tone_frequencies_hz: tones (Hz).
        sample_rate_hz: loop sample rate (Hz).
        coefficients: complex (T, C, C) adaptation matrices.
        mu_max: upper end of the search.
        rtol: relative accuracy of the bisection.
    """
    def stable(mu: float) -> bool:
        rho = closed_loop_spectral_radius(plant, tone_frequencies_hz, sample_rate_hz,
                                          coefficients, mu)
        return rho < 1.0

    grid = np.geomspace(mu_max * 1e-6, mu_max, 241)
    if not stable(grid[0]):
        return 0.0
    lo = grid[0]
    for hi in grid[1:]:
        if not stable(hi):
            break
        lo = hi
    else:
        return float(mu_max)
    while hi - lo > rtol * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return float(lo)


def normalized_coefficients(G: np.ndarray, mode: str,
                            max_condition: float = MAX_CONDITION_NUMBER) -> np.ndarray:
    """Adaptation coefficients P_t making ``mu`` a normalised convergence rate.

    Args:
        G: plant responses, complex (T, C, C) (or one (C, C) matrix).
        mode: ``"centralized"``: ``P_t = -2 G_t^{-1}`` (M = I, all modes at rate mu);
            ``"decentralized"``: ``P_t = diag(-2 / G_t[i, i])`` (the paper's six SISO loops,
            each normalised by its own strut's gain and phase; stable only if the coupling
            leaves every eigenvalue of ``diag(1/G_ii) G`` in the right half plane, check with
            :func:`mu_bound`); ``"raw"``: ``P_t = I`` (the paper as printed).
        max_condition: largest accepted 2-norm condition number of G_t (centralized).

    Returns:
        Complex P with the shape of G.

    Raises:
        ValueError: unknown mode, non-finite G, ill-conditioned G_t or a zero diagonal.
    """
    g = _as_stack(G)
    if mode not in ADAPTATION_MODES:
        raise ValueError(f"mode must be one of {ADAPTATION_MODES}, got {mode!r}")
    if not np.all(np.isfinite(g)):
        raise ValueError("G must be finite")
    c = g.shape[1]
    if mode == "raw":
        p = np.broadcast_to(np.eye(c, dtype=complex), g.shape).copy()
    elif mode == "centralized":
        cond = np.linalg.cond(g)
        if not np.all(cond <= max_condition):
            raise ValueError(f'G is ill-conditioned (condition numbers {np.round(cond, 1)}, '
                             f'limit {max_condition:g}): use "decentralized"')
        p = -2.0 * np.linalg.solve(g, np.broadcast_to(np.eye(c), g.shape))
    else:
        diag = np.diagonal(g, axis1=1, axis2=2)
        scale = np.max(np.abs(g), axis=(1, 2), keepdims=True)[:, :, 0]
        if np.any(np.abs(diag) <= 1e-9 * scale) or np.any(scale == 0.0):
            raise ValueError("G has a (near) zero diagonal entry: decentralized P undefined")
        p = (-2.0 / diag)[:, :, None] * np.eye(c)
    return p[0] if np.ndim(G) < 3 else p


def schroeder_phases(n_tones: int) -> np.ndarray:
    """Schroeder phases (rad) giving a low crest factor for equal-amplitude multisines."""
    k = np.arange(1, n_tones + 1)
    return -np.pi * k * (k - 1) / max(n_tones, 1)


MAX_MISSING_FRACTION = 0.05
"""Largest fraction of an identification's measured samples that may be missing (samples
the controller never received: gaps of the loop); beyond it the run is refused."""


class SampledRun:
    """Bookkeeping of an identification run of ``_total`` samples at ``_fs`` (Hz).

    Samples the controller never received are :meth:`skip`-ped: the run keeps its timing
    (the excitation and the phase references move on by the sample index) and those
    samples are left out of the fit; ``missing`` counts the measured ones among them.
    """

    _n: int
    _total: int
    _fs: float
    _c: int
    _seg_len: int
    _u: np.ndarray
    missing: int = 0
    """Measured samples (past each segment's settling) the run did not receive."""

    def skip(self, samples: int) -> None:
        """``samples`` samples of the run were not received (a gap before the next one)."""
        for _ in range(min(int(samples), self._total - self._n)):
            seg, k = divmod(self._n, self._seg_len)
            self._skip_one(seg, k)
            self._n += 1

    def _skip_one(self, seg: int, k: int) -> None:
        """Leave sample ``k`` of segment ``seg`` out (the run's own bookkeeping)."""
        raise NotImplementedError

    @property
    def measured_samples(self) -> int:
        """Samples of the run that are measured (not settling)."""
        raise NotImplementedError

    def missing_refusal(self) -> str:
        """Why the run cannot be used because of missing samples ("" if it can)."""
        total = self.measured_samples
        if self.missing <= MAX_MISSING_FRACTION * total:
            return ""
        return (f"{self.missing} of its {total} measured samples "
                f"({100.0 * self.missing / total:.1f} %) missing "
                f"(> {100.0 * MAX_MISSING_FRACTION:.0f} %)")

    def _position(self, error: np.ndarray) -> tuple[np.ndarray, int, int] | None:
        """Check the error (C,), clear the command; (error, segment, sample in it) or None.

        None once the run is over: the command stays zero.
        """
        e = np.asarray(error, dtype=float)
        if e.shape != (self._c,):
            raise ValueError(f"error must have shape ({self._c},), got {e.shape}")
        self._u[:] = 0.0
        if self._n >= self._total:
            return None
        seg, k = divmod(self._n, self._seg_len)
        return e, seg, k

    @property
    def done(self) -> bool:
        """True once every sample of the run has been taken."""
        return self._n >= self._total

    @property
    def progress(self) -> float:
        """Fraction of the run completed, in [0, 1]."""
        return min(1.0, self._n / self._total)

    @property
    def total_samples(self) -> int:
        """Samples of the whole run (settling included)."""
        return self._total

    @property
    def duration_s(self) -> float:
        """Total duration of the run (s)."""
        return self._total / self._fs


class ToneResponseIdentifier(SampledRun):
    """Measure the plant response G (T, C, C) at the tones on a running plant.

    Same step interface as the canceller (error of sample n in, command of sample n out).
    The run has C + 2 segments of ``settle_s + measure_s`` each: a baseline (no excitation),
    then channel j = 0..C-1 excited with every tone at once (``amplitude_n`` each, Schroeder
    phases), then a second baseline. In each segment the first ``settle_s`` are discarded and
    the error is fitted by least squares on ``[1, cos phi_t, sin phi_t]`` over ``measure_s``,
    giving phasors Y[t, i] in the canceller's convention and phase accumulators. Then
    ``G[t, :, j] = (Y_j - Y_baseline) / X_t`` with the baseline interpolated linearly in time
    between the two baseline segments (equal to their mean for a stationary disturbance).
    The subtraction removes a stationary disturbance at the tones (the shaker keeps running)
    and any frozen canceller output. With the defaults and 6 channels the run takes
    8 x 0.4 s = 3.2 s. ``settle_s`` must cover the plant's transient after the excitation
    switches channel; other tones in the error that are not in the list leak into the fit
    unless they are well separated (> ~2 / measure_s Hz) from the tones.

    Args:
        n_channels: number of channels C.
        tone_frequencies_hz: tones (Hz), in (0, fs/2), no duplicates.
        sample_rate_hz: loop sample rate (Hz).
        amplitude_n: excitation amplitude per tone (N), scalar or (T,).
        settle_s: discarded settling time per segment (s).
        measure_s: fitted time per segment (s).
    """

    def __init__(self, n_channels: int, tone_frequencies_hz: Sequence[float] | np.ndarray,
                 sample_rate_hz: float, amplitude_n: float | np.ndarray = 2.0,
                 settle_s: float = 0.1, measure_s: float = 0.3) -> None:
        """Validate the arguments (ValueError) and allocate the segment buffers."""
        self._c = int(n_channels)
        if self._c != n_channels or self._c < 1:
            raise ValueError(f"n_channels must be a positive integer, got {n_channels!r}")
        self._fs = float(sample_rate_hz)
        self._freqs = validate_frequencies(tone_frequencies_hz, self._fs)
        if self._freqs.size == 0:
            raise ValueError("at least one tone frequency is required")
        t = self._freqs.size
        amp = np.broadcast_to(np.asarray(amplitude_n, dtype=float), (t,))
        if not np.all(np.isfinite(amp)) or np.any(amp <= 0.0):
            raise ValueError(f"amplitude_n must be finite and > 0, got {amplitude_n!r}")
        self._settle = int(round(settle_s * self._fs))
        self._measure = int(round(measure_s * self._fs))
        if self._settle < 0 or self._measure < 2 * (2 * t + 1):
            raise ValueError("settle_s must be >= 0 and measure_s must hold > 2(2T+1) samples")
        self._x = amp * np.exp(1j * schroeder_phases(t))
        self._dphi = TWO_PI * self._freqs / self._fs
        self._phi = np.zeros(t)
        self._seg_len = self._settle + self._measure
        self._n_seg = self._c + 2
        self._total = self._n_seg * self._seg_len
        self._regress = np.zeros((self._measure, 1 + 2 * t))
        self._errors = np.zeros((self._measure, self._c))
        self._y = np.zeros((self._n_seg, t, self._c), dtype=complex)
        self._u = np.zeros(self._c)
        self._n = 0

    def step(self, error: np.ndarray) -> np.ndarray:
        """Record the error of sample n (m/s^2, (C,)) and return the command (N, (C,))."""
        position = self._position(error)
        if position is None:
            return self._u.copy()
        e, seg, k = position
        if k >= self._settle:
            row = k - self._settle
            t = self._freqs.size
            self._regress[row, 0] = 1.0
            self._regress[row, 1:1 + t] = np.cos(self._phi)
            self._regress[row, 1 + t:] = np.sin(self._phi)
            self._errors[row] = e
            if row == self._measure - 1:
                self._y[seg] = self._fit()
        if 1 <= seg <= self._c:
            self._u[seg - 1] = np.sum((self._x * np.exp(1j * self._phi)).real)
        self._phi += self._dphi
        np.remainder(self._phi, TWO_PI, out=self._phi)
        self._n += 1
        return self._u.copy()

    def excitation_ahead(self, samples: int) -> np.ndarray:
        """The commands (N, (samples, C)) of the run's next ``samples`` samples (0 past its end)."""
        steps = np.arange(int(samples))
        ahead = self._n + steps
        segment = ahead // self._seg_len
        phases = self._phi + np.outer(steps, self._dphi)                  # (samples, T) rad
        value = (self._x * np.exp(1j * phases)).real.sum(axis=1)
        rows = np.zeros((steps.size, self._c))
        on = (segment >= 1) & (segment <= self._c) & (ahead < self._total)
        rows[np.flatnonzero(on), segment[on] - 1] = value[on]
        return rows

    def _skip_one(self, seg: int, k: int) -> None:
        """A missing sample: a zero row (no equation) in the segment's fit, phase moved on."""
        if k >= self._settle:
            row = k - self._settle
            self._regress[row] = 0.0
            self._errors[row] = 0.0
            self.missing += 1
            if row == self._measure - 1:
                self._y[seg] = self._fit()
        self._phi += self._dphi
        np.remainder(self._phi, TWO_PI, out=self._phi)

    @property
    def measured_samples(self) -> int:
        """Samples fitted over the run (every segment's measured part)."""
        return self._n_seg * self._measure

    def _fit(self) -> np.ndarray:
        """Least-squares phasors Y (T, C) = a - j b of the buffered segment.

        A missing sample's row is zero: it adds no equation to the fit.
        """
        coef, *_ = np.linalg.lstsq(self._regress, self._errors, rcond=None)
        t = self._freqs.size
        return coef[1:1 + t] - 1j * coef[1 + t:]


    @property
    def tone_frequencies_hz(self) -> np.ndarray:
        """Tones (Hz), a copy."""
        return self._freqs.copy()

    def baseline_change(self) -> np.ndarray:
        """Per tone, how far the disturbance moved between the two baselines (T,).

        ``|Y_last - Y_first|`` (norm over the channels) divided by the norm of the
        excited channels' response ``Y_j - baseline``: 0 for a stationary disturbance at
        the tone; of order 1 when a disturbance a fraction of a hertz away rotates
        through the fit (the baseline subtraction then corrupts G by as much).

        Raises:
            RuntimeError: if the run is not finished.
        """
        if not self.done:
            raise RuntimeError(f"identification not finished ({100 * self.progress:.0f} %)")
        change = np.linalg.norm(self._y[-1] - self._y[0], axis=1)                  # (T,)
        base = 0.5 * (self._y[0] + self._y[-1])
        response = np.linalg.norm(self._y[1:-1] - base[None], axis=2)            # (C, T)
        return change / np.maximum(np.median(response, axis=0), 1e-300)

    def result(self) -> np.ndarray:
        """Measured plant response G (T, C, C), complex (m/s^2 per N).

        Raises:
            RuntimeError: if the run is not finished.
        """
        if not self.done:
            raise RuntimeError(f"identification not finished ({100 * self.progress:.0f} %)")
        w = np.arange(1, self._c + 1) / (self._c + 1)
        base = (1.0 - w)[:, None, None] * self._y[0] + w[:, None, None] * self._y[-1]
        resp = (self._y[1:-1] - base) / self._x[None, :, None]
        return np.transpose(resp, (1, 2, 0))
