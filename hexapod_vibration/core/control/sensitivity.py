"""Predicted closed-loop sensitivity of the adapting canceller, from G(f) and its settings.

The canceller is exactly linear and time invariant (Glover 1977; Bodson, Sacks & Khosla
1994; :func:`~hexapod_vibration.core.control.adaptation.canceller_state_space`). With the
phase-rotated weights ``V_t = W_t e^{j phi_t}``, ``V_{n+1} = e^{j w_t} (V_n + mu_t P_t e_n)``
and ``u_n = sum_t Re{V_t,n + mu_t P_t e_n}``, so from the real error e to the command u

    K(z) = sum_t (mu_t / 2) [P_t z / (z - e^{j w_t}) + conj(P_t) z / (z - e^{-j w_t})],

``w_t = 2 pi f_t / fs``: a pair of poles on the unit circle at every tone. With the plant
``e = G u + d`` (G with the pairing of docs/architecture.md, as identified) the loop is
positive feedback, ``e = S d`` with

    S(f) = (I - G(f) K(f))^{-1},

the error with control per error without it. ``S`` is 0 at the tones (the notches) and
tends to I far from them; next to a tone it can exceed 1 (the waterbed): the phase of the
weight loop's modes (the eigenvalues of ``-(1/2) P_t G``, 1 for the normalised P at the
tone) turns with frequency and with the coupling between struts, and the tones' loops add.
Measured on a spectrum this is the ratio of the controlled to the uncontrolled level.

Three views of S per frequency (:class:`SensitivityPrediction`):
- ``strut``: the six SISO strut loops of the decentralized design, ``1 / (1 - G_ii K_ii)``
  (coupling ignored: what each strut's controller sees alone);
- ``sigma_max``: the largest singular value of the 6x6 S (the worst direction of any
  disturbance; the bound used by :mod:`~hexapod_vibration.core.control.mu_policy`);
- ``output``: one output combination ``c`` (the z axis: ``c = row 2 of J^-1``) for a
  disturbance of cross-spectral density ``Phi`` (C, C) per frequency,
  ``sqrt(c^T S Phi S^H c / c^T Phi c)``: the ratio a spectrum of that output measures.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from hexapod_vibration.core.control.notch import validate_frequencies
from hexapod_vibration.core.control.notch_weights import update_lowpass_response

DEFAULT_GRID_STEP_HZ = 0.1
REFERENCE_MU = 0.002
NEAR_TONE_SPAN_HZ = 5.0
METRICS = ("sigma_max", "strut", "output")
POLE_GUARD = 1e-12

PlantResponse = Callable[[np.ndarray], np.ndarray]


def tone_rates(mu: float | Sequence[float] | np.ndarray, n_tones: int) -> np.ndarray:
    """Per-tone rates (T,) from one ``mu`` or T of them (finite, >= 0), or ValueError."""
    rates = np.broadcast_to(np.asarray(mu, dtype=float), (n_tones,)).copy() \
        if np.ndim(mu) == 0 else np.asarray(mu, dtype=float).reshape(-1)
    if rates.shape != (n_tones,):
        raise ValueError(f"expected one rate or {n_tones} per-tone rates, got {rates.size}")
    if not np.all(np.isfinite(rates)) or np.any(rates < 0.0):
        raise ValueError(f"rates must be finite and >= 0, got {rates.tolist()}")
    return rates


def per_tone_coefficients(coefficients: np.ndarray, mu: float,
                          tone_mu: Sequence[float] | np.ndarray) -> np.ndarray:
    """Coefficients ``P_t mu_t / mu`` (T, C, C): per-tone rates in a one-``mu`` canceller.

    The canceller's update ``W_t += mu P_t e e^{-j phi_t}`` with these coefficients is the
    update with ``mu_t P_t``: a per-tone rate needs no change to the canceller.

    Raises:
        ValueError: ``mu`` not > 0, or rates of the wrong length or sign.
    """
    p = np.asarray(coefficients, dtype=complex)
    if not np.isfinite(mu) or mu <= 0.0:
        raise ValueError(f"mu must be > 0 to fold per-tone rates into P, got {mu!r}")
    rates = tone_rates(tone_mu, p.shape[0])
    return p * (rates / mu)[:, None, None]


def _off_pole(distance: np.ndarray) -> np.ndarray:
    """``z - pole`` with exact hits moved 1e-12 away: K is then finite but huge, S ~ 0."""
    return np.where(np.abs(distance) < POLE_GUARD, POLE_GUARD, distance)


def canceller_frequency_response(
    tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
    coefficients: np.ndarray, mu: float | Sequence[float] | np.ndarray,
    frequencies_hz: Sequence[float] | np.ndarray, radius: float = 1.0,
    integral_ratio: float | Sequence[float] | np.ndarray = 0.0,
    update_lowpass_hz: float = 0.0,
) -> np.ndarray:
    """K (F, C, C) of the adapting canceller from error to command (closed form).

    With the type-2 update (:meth:`AdaptiveNotchCanceller.set_integral_ratio`,
    ``kappa_t = ratio_t mu_t``) each tone's ``z / (z - p)`` becomes
    ``g + kappa_t g^2`` with ``g = z / (z - p)`` (the rate integrates the same correction).
    With the update low-pass (:meth:`AdaptiveNotchCanceller.set_update_lowpass`) each branch
    is further multiplied by the filter at baseband, ``L(z / p)`` and ``L(z p)``.

    Args:
        tone_frequencies_hz: tones f_t (Hz).
        sample_rate_hz: loop rate fs (Hz).
        coefficients: complex (T, C, C) adaptation matrices P_t.
        mu: one rate, or one per tone (T,).
        frequencies_hz: where to evaluate (Hz); ``z = radius e^{j 2 pi f / fs}``.
        radius: |z| (1: the frequency response; slightly > 1 for a Nyquist contour that
            passes outside the canceller's poles).
        integral_ratio: the type-2 ratio, one or per tone (0: the first-order update).
        update_lowpass_hz: corner of the update low-pass (Hz; 0: none).
    """
    tones = validate_frequencies(tone_frequencies_hz, sample_rate_hz)
    p = np.asarray(coefficients, dtype=complex)
    if p.ndim != 3 or p.shape[0] != tones.size or p.shape[1] != p.shape[2]:
        raise ValueError(f"coefficients must be ({tones.size}, C, C), got {p.shape}")
    rates = tone_rates(mu, tones.size)
    f = np.asarray(frequencies_hz, dtype=float).reshape(-1)
    z = radius * np.exp(2j * np.pi * f / sample_rate_hz)                 # (F,)
    pole = np.exp(2j * np.pi * tones / sample_rate_hz)                    # (T,)
    g_pos = z[:, None] / _off_pole(z[:, None] - pole[None, :])            # (F, T)
    g_neg = z[:, None] / _off_pole(z[:, None] - np.conj(pole)[None, :])
    kappa = tone_rates(integral_ratio, tones.size) * rates                # (T,)
    if np.any(kappa > 0.0):
        g_pos = g_pos * (1.0 + kappa[None, :] * g_pos)
        g_neg = g_neg * (1.0 + kappa[None, :] * g_neg)
    if update_lowpass_hz > 0.0:
        g_pos = g_pos * update_lowpass_response(update_lowpass_hz, sample_rate_hz,
                                                z[:, None] * np.conj(pole)[None, :])
        g_neg = g_neg * update_lowpass_response(update_lowpass_hz, sample_rate_hz,
                                                z[:, None] * pole[None, :])
    half = 0.5 * rates[:, None, None] * p                                 # (T, C, C)
    return (np.einsum("ft,tij->fij", g_pos, half)
            + np.einsum("ft,tij->fij", g_neg, np.conj(half)))


def sensitivity_matrix(plant: np.ndarray, canceller: np.ndarray) -> np.ndarray:
    """``S = (I - G K)^{-1}`` (F, C, C) from G and K (F, C, C)."""
    g, k = np.asarray(plant, dtype=complex), np.asarray(canceller, dtype=complex)
    eye = np.eye(g.shape[-1])
    return np.linalg.inv(eye - g @ k)


def strut_sensitivity(plant: np.ndarray, canceller: np.ndarray) -> np.ndarray:
    """``1 / (1 - G_ii K_ii)`` (F, C): each strut's SISO loop, coupling ignored."""
    g = np.diagonal(np.asarray(plant, dtype=complex), axis1=1, axis2=2)
    k = np.diagonal(np.asarray(canceller, dtype=complex), axis1=1, axis2=2)
    return 1.0 / (1.0 - g * k)


def output_sensitivity(sensitivity: np.ndarray, output_weights: np.ndarray,
                       disturbance_csd: np.ndarray | None = None) -> np.ndarray:
    """``sqrt(c^T S Phi S^H c / c^T Phi c)`` (F,): the spectrum ratio of ``c^T e``.

    Args:
        sensitivity: S (F, C, C).
        output_weights: c (C,), e.g. row 2 of ``J^-1`` for the top plate's z axis.
        disturbance_csd: Phi (F, C, C) (Hermitian), the cross-spectral density of the
            error without control; None: equal, uncorrelated disturbances (Phi = I).
    """
    s = np.asarray(sensitivity, dtype=complex)
    c = np.asarray(output_weights, dtype=float).reshape(-1)
    phi = (np.broadcast_to(np.eye(c.size), s.shape) if disturbance_csd is None
           else np.asarray(disturbance_csd, dtype=complex))
    row = np.einsum("i,fij->fj", c, s)                                    # c^T S
    num = np.einsum("fi,fij,fj->f", row, phi, np.conj(row)).real
    den = np.einsum("i,fij,j->f", c, phi, c).real
    return np.sqrt(np.maximum(num, 0.0) / np.maximum(den, 1e-300))


def prediction_grid(tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
                    mu: float | Sequence[float] | np.ndarray = REFERENCE_MU,
                    step_hz: float = DEFAULT_GRID_STEP_HZ) -> np.ndarray:
    """Frequencies (Hz) in [0, fs/2]: a uniform grid plus log-spaced points beside each tone.

    A tone's notch is about ``mu_t fs / (2 pi)`` Hz wide (0.3 Hz for mu = 0.002), and the
    rise beside it peaks at a distance of that order whatever mu (its height depends on
    the weight loop's phase, not on mu). Offsets from 1/100 of that width out to 5 Hz,
    log-spaced (64 per decade) on both sides, resolve it at any rate.

    Args:
        tone_frequencies_hz: tones (Hz).
        sample_rate_hz: loop rate (Hz).
        mu: one rate or one per tone (sets the notches' widths; 0 counts as 1e-9).
        step_hz: uniform step (Hz) over 0..fs/2.
    """
    fs = float(sample_rate_hz)
    tones = validate_frequencies(tone_frequencies_hz, fs)
    rates = np.maximum(tone_rates(mu, tones.size), 1e-9)
    if not step_hz > 0.0:
        raise ValueError(f"step_hz must be > 0, got {step_hz!r}")
    parts = [np.arange(0.0, 0.5 * fs, step_hz), [0.5 * fs]]
    for tone, rate in zip(tones, rates, strict=True):
        smallest = min(0.01 * rate * fs / (2.0 * np.pi), 0.1 * NEAR_TONE_SPAN_HZ)
        decades = np.log10(NEAR_TONE_SPAN_HZ / smallest)
        offsets = np.geomspace(smallest, NEAR_TONE_SPAN_HZ, int(np.ceil(64 * decades)) + 1)
        parts += [tone - offsets, tone + offsets, [tone]]
    f = np.unique(np.concatenate(parts))
    return f[(f >= 0.0) & (f <= 0.5 * fs)]


@dataclass(frozen=True)
class SensitivityPrediction:
    """|S| (linear, not dB) over a frequency grid, in the three views of the module.

    Attributes:
        frequencies_hz: grid (F,) (Hz).
        tone_frequencies_hz: the canceller's tones (Hz).
        matrix: S (F, C, C), complex.
        strut: |1 / (1 - G_ii K_ii)| (F, C).
        output: the output combination's spectrum ratio (F,), or None if not asked.
        stable: whether the closed loop is stable (Nyquist, :func:`closed_loop_is_stable`);
            None if not checked. |S| means nothing for an unstable loop.
    """

    frequencies_hz: np.ndarray
    tone_frequencies_hz: np.ndarray
    matrix: np.ndarray
    strut: np.ndarray
    output: np.ndarray | None
    stable: bool | None

    @cached_property
    def sigma_max(self) -> np.ndarray:
        """Largest singular value of S (F,) (computed on first use)."""
        return np.linalg.svd(self.matrix, compute_uv=False)[:, 0]

    def values(self, metric: str) -> np.ndarray:
        """|S| (F,) of ``metric`` (``sigma_max``, ``strut`` (worst strut) or ``output``)."""
        if metric == "sigma_max":
            return self.sigma_max
        if metric == "strut":
            return self.strut.max(axis=1)
        if metric == "output":
            if self.output is None:
                raise ValueError("no output sensitivity: give output_weights")
            return self.output
        raise ValueError(f"metric must be one of {METRICS}, got {metric!r}")

    def db(self, metric: str = "sigma_max") -> np.ndarray:
        """``20 log10 |S|`` (F,) of ``metric``."""
        return 20.0 * np.log10(np.maximum(self.values(metric), 1e-300))

    def largest_rise(self, metric: str = "sigma_max") -> tuple[float, float]:
        """(largest rise in dB, its frequency in Hz) over the grid; inf if unstable.

        |S| < 1 inside every notch, so the largest value of ``20 log10 |S|`` lies outside
        the tones (it is the amplification the canceller adds somewhere, >= ~0 dB far
        from the tones where S tends to I).
        """
        if self.stable is False:
            return float("inf"), float("nan")
        db = self.db(metric)
        k = int(np.argmax(db))
        return float(db[k]), float(self.frequencies_hz[k])

    def db_at(self, frequencies_hz: np.ndarray) -> np.ndarray:
        """``20 log10 |S|`` (dB) at ``frequencies_hz``, interpolated on the grid.

        The output's |S| when the prediction has one (the ratio for the disturbance's own
        direction, what the mu policy bounds), else the worst strut's.
        """
        metric = "output" if self.output is not None else "strut"
        return np.interp(np.asarray(frequencies_hz, dtype=float), self.frequencies_hz,
                         self.db(metric))

    def table_db(self) -> dict[str, np.ndarray]:
        """The prediction as named columns (F,): ``frequency_hz``, then dB of |S|.

        ``sigma_max_db``, ``strut<k>_db`` (k = 1..C) and, when there is one, ``output_db``
        (the rows of ``/pph/notch_sensitivity``).
        """
        rows = {"frequency_hz": self.frequencies_hz, "sigma_max_db": self.db("sigma_max")}
        strut_db = 20.0 * np.log10(np.maximum(self.strut, 1e-300))
        rows.update({f"strut{k + 1}_db": strut_db[:, k] for k in range(strut_db.shape[1])})
        if self.output is not None:
            rows["output_db"] = self.db("output")
        return rows


def _plant_at(plant: PlantResponse | np.ndarray, frequencies_hz: np.ndarray) -> np.ndarray:
    g = plant(frequencies_hz) if callable(plant) else np.asarray(plant, dtype=complex)
    g = np.asarray(g, dtype=complex)
    if g.ndim != 3 or g.shape[0] != frequencies_hz.size or g.shape[1] != g.shape[2]:
        raise ValueError(f"plant response must be ({frequencies_hz.size}, C, C), "
                         f"got {g.shape}")
    return g


def closed_loop_is_stable(plant: PlantResponse, tone_frequencies_hz: Sequence[float] | np.ndarray,
                          sample_rate_hz: float, coefficients: np.ndarray,
                          mu: float | Sequence[float] | np.ndarray,
                          frequencies_hz: np.ndarray | None = None,
                          max_refinements: int = 60,
                          integral_ratio: float | Sequence[float] | np.ndarray = 0.0,
                          update_lowpass_hz: float = 0.0) -> bool:
    """Nyquist test of the loop G + canceller from G's frequency response (G stable).

    The closed-loop poles are the zeros of ``det(I - G(z) K(z))``. With G stable and
    strictly proper and K's poles on the unit circle, the contour ``|z| = 1 + eps`` (eps =
    1e-3 of the slowest weight mode's rate ``|mu_t lambda|``, far inside the notches) has
    every open-loop pole inside, and the winding number of the determinant along it is
    minus the number of closed-loop poles outside: the loop is stable iff it is 0. G is
    taken on the unit circle (it is smooth on the scale of eps); K exactly on the contour.
    The real system's symmetry halves the contour (0..fs/2, twice the phase change); the
    grid is refined where the determinant's phase jumps by more than pi/4 between
    neighbours (a contour still unresolved after ``max_refinements`` rounds counts as
    unstable).

    Args:
        plant: callable frequencies (Hz) -> G (F, C, C), e.g. the ``at`` of an identified
            ``PlantFrequencyResponse``.
        tone_frequencies_hz: the canceller's tones (Hz).
        sample_rate_hz: loop rate (Hz).
        coefficients: complex (T, C, C) P_t.
        mu: one rate or one per tone (T,).
        frequencies_hz: starting grid (default :func:`prediction_grid`).
        max_refinements: bisection rounds of the grid.
        integral_ratio: the canceller's type-2 ratio (see :func:`canceller_frequency_response`;
            its double poles sit on the same circle, inside the contour).
        update_lowpass_hz: corner of the update low-pass (Hz; 0: none; its poles
            ``a e^{+-j w_t}`` lie inside the unit circle).
    """
    fs = float(sample_rate_hz)
    tones = validate_frequencies(tone_frequencies_hz, fs)
    rates = tone_rates(mu, tones.size)
    if not np.any(rates > 0.0):
        return True
    p = np.asarray(coefficients, dtype=complex)
    lam = np.linalg.eigvals(-0.5 * p @ _plant_at(plant, tones))          # (T, C)
    scale = np.abs(rates[:, None] * lam)
    radius = 1.0 + 1e-3 * max(float(np.min(scale[scale > 0.0], initial=1.0)), 1e-9)
    f = prediction_grid(tones, fs, rates) if frequencies_hz is None else np.unique(frequencies_hz)
    # Within ~eps of a pole the determinant turns by up to C half-turns (a pole of order
    # C): points log-spaced from eps/100 keep every step's turn well below pi, so no
    # wrapped increment can hide a whole turn.
    eps_hz = (radius - 1.0) * fs / (2.0 * np.pi)
    close = eps_hz * np.geomspace(1e-2, 1e5, 281)
    f = np.unique(np.concatenate([f, [0.0, 0.5 * fs], *[t + close for t in tones],
                                  *[t - close for t in tones]]))
    f = f[(f >= 0.0) & (f <= 0.5 * fs)]

    def det_on_contour(freqs: np.ndarray) -> np.ndarray:
        g = _plant_at(plant, freqs)
        k = canceller_frequency_response(tones, fs, coefficients, rates, freqs, radius,
                                         integral_ratio, update_lowpass_hz)
        return np.linalg.det(np.eye(g.shape[1]) - g @ k)

    d = det_on_contour(f)
    for _ in range(max_refinements):
        jump = np.abs(np.angle(d[1:] / d[:-1]))
        bad = np.flatnonzero(jump > np.pi / 4)
        if bad.size == 0:
            break
        mid = 0.5 * (f[bad] + f[bad + 1])
        f = np.concatenate([f, mid])
        d = np.concatenate([d, det_on_contour(mid)])
        order = np.argsort(f)
        f, d = f[order], d[order]
    else:
        return False                                  # unresolved: not shown to be stable
    if np.any(d == 0.0):
        return False
    winding = np.sum(np.angle(d[1:] / d[:-1])) / np.pi    # 2 x (phase change 0..fs/2) / 2 pi
    return int(np.rint(winding)) == 0


def predict_sensitivity(plant: PlantResponse, tone_frequencies_hz: Sequence[float] | np.ndarray,
                        sample_rate_hz: float, coefficients: np.ndarray,
                        mu: float | Sequence[float] | np.ndarray,
                        frequencies_hz: np.ndarray | None = None,
                        output_weights: np.ndarray | None = None,
                        disturbance_csd: PlantResponse | np.ndarray | None = None,
                        check_stability: bool = True,
                        update_lowpass_hz: float = 0.0) -> SensitivityPrediction:
    """|S(f)| of the loop G + canceller (tones, P_t, mu or per-tone rates), before control.

    Args:
        plant: callable frequencies (Hz) -> G (F, C, C) (an identified
            :class:`~hexapod_vibration.core.control.plant_identification.PlantFrequencyResponse`'s
            ``at``, or an exact model).
        tone_frequencies_hz: the canceller's tones (Hz).
        sample_rate_hz: loop rate (Hz).
        coefficients: complex (T, C, C) P_t.
        mu: one rate or one per tone (T,).
        frequencies_hz: grid (Hz); default :func:`prediction_grid`.
        output_weights: c (C,) for the ``output`` view (e.g. the z row of ``J^-1``).
        disturbance_csd: Phi for the ``output`` view, (F, C, C) on the grid or a callable
            of the frequencies; None: Phi = I.
        check_stability: run :func:`closed_loop_is_stable`.
        update_lowpass_hz: corner of the canceller's update low-pass (Hz; 0: none).
    """
    fs = float(sample_rate_hz)
    tones = validate_frequencies(tone_frequencies_hz, fs)
    f = prediction_grid(tones, fs, mu) if frequencies_hz is None else np.asarray(
        frequencies_hz, dtype=float).reshape(-1)
    g = _plant_at(plant, f)
    k = canceller_frequency_response(tones, fs, coefficients, mu, f,
                                     update_lowpass_hz=update_lowpass_hz)
    s = sensitivity_matrix(g, k)
    out = None
    if output_weights is not None:
        phi = disturbance_csd(f) if callable(disturbance_csd) else disturbance_csd
        out = output_sensitivity(s, output_weights, phi)
    stable = (closed_loop_is_stable(plant, tones, fs, coefficients, mu,
                                    update_lowpass_hz=update_lowpass_hz)
              if check_stability else None)
    return SensitivityPrediction(f, tones, s, np.abs(strut_sensitivity(g, k)), out, stable)


def stable_mu_limit(plant: PlantResponse, tone_frequencies_hz: Sequence[float] | np.ndarray,
                    sample_rate_hz: float, coefficients: np.ndarray, mu_max: float = 1.0,
                    rtol: float = 0.01, update_lowpass_hz: float = 0.0) -> float:
    """Largest common rate (to ``rtol``) the Nyquist test finds stable, from G's response.

    The exact counterpart, for a measured G, of
    :func:`~hexapod_vibration.core.control.adaptation.exact_mu_bound` (which needs a state
    space model): the averaged bound of eq. 18 looks only at the tones, this one at the
    whole loop (the canceller's gain far from its tones meets the plant's resonances).
    Scans a log grid from ``mu_max * 1e-6`` up, then bisects the first unstable interval;
    0.0 if even the smallest rate is unstable, ``mu_max`` if all are stable.
    """
    def stable(mu: float) -> bool:
        return closed_loop_is_stable(plant, tone_frequencies_hz, sample_rate_hz,
                                     coefficients, mu, update_lowpass_hz=update_lowpass_hz)

    grid = np.geomspace(mu_max * 1e-6, mu_max, 25)
    if not stable(grid[0]):
        return 0.0
    lo = grid[0]
    for hi in grid[1:]:
        if not stable(hi):
            break
        lo = hi
    else:
        return float(mu_max)
    while hi > lo * (1.0 + rtol):
        mid = float(np.sqrt(lo * hi))
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return float(lo)
