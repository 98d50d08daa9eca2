"""Adaptation rates that keep the promise: a predicted rise off the tones within a limit.

The canceller's ``mu`` sets how fast it converges (time constant ``1/(mu fs)`` with the
normalised coefficients) and how wide its notches are; wider notches next to each other,
a weight loop whose modes turn in phase with frequency, or coupled struts make the closed
loop amplify the disturbance beside the tones (|S| > 1, the waterbed;
:mod:`~hexapod_vibration.core.control.sensitivity`). Given the identified G(f), the tones,
their coefficients P_t and the set ``mu``:

- ``manual``: every tone adapts at ``mu``; the predicted rise is reported and a warning
  given when it exceeds ``max_rise_db`` (or the loop would be unstable);
- ``auto``: per tone the largest rate ``mu_t <= mu`` whose predicted rise stays within
  ``max_rise_db``: first one common scale of all rates (bisection), then each tone alone
  raised back towards ``mu`` as far as the limit allows (bisection, the others fixed).

The canceller has one ``mu``; per-tone rates go into its coefficients as
``P_t mu_t / mu`` (:func:`~hexapod_vibration.core.control.sensitivity.per_tone_coefficients`).
The rise is the largest ``20 log10 |S|`` over 0..fs/2 in the chosen view (default the
6x6 loop's largest singular value, which bounds every disturbance direction).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.control import sensitivity
from hexapod_vibration.core.control.notch import validate_frequencies

DEFAULT_MAX_RISE_DB = 3.0
MU_POLICIES = ('manual', 'auto')
BISECTION_STEPS = 24
SMALLEST_SCALE = 1e-6


@dataclass(frozen=True)
class MuChoice:
    """The rates a policy chose and what they predict.

    Attributes:
        policy: ``manual`` or ``auto``.
        mu: the set rate (the ceiling of ``auto``).
        tone_mu: per-tone rates (T,).
        max_rise_db: the limit (dB).
        predicted_rise_db: largest predicted ``20 log10 |S|`` with ``tone_mu`` (dB; inf if
            the loop would be unstable).
        rise_at_hz: where it is (Hz; NaN if unstable).
        metric: the view of S (``sigma_max``, ``strut`` or ``output``).
        warning: a one-line reason when the prediction breaks the limit, else None.
    """

    policy: str
    mu: float
    tone_mu: np.ndarray
    max_rise_db: float
    predicted_rise_db: float
    rise_at_hz: float
    metric: str
    warning: str | None

    @property
    def within_limit(self) -> bool:
        """True when the predicted rise is within ``max_rise_db``."""
        return self.predicted_rise_db <= self.max_rise_db


def validate_policy(policy: str, max_rise_db: float) -> tuple[str, float]:
    """Return ``(policy, max_rise_db)`` checked, or raise ValueError with the reason."""
    if policy not in MU_POLICIES:
        raise ValueError(f'mu_policy must be one of {MU_POLICIES}, got {policy!r}')
    value = float(max_rise_db)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f'max_rise_db must be finite and > 0 dB, got {max_rise_db!r}')
    return policy, value


class _RiseEvaluator:
    """Predicted rise (dB) and stability for candidate per-tone rates, on a fixed grid."""

    def __init__(self, plant: sensitivity.PlantResponse, tones: np.ndarray, fs: float,
                 coefficients: np.ndarray, metric: str,
                 frequencies_hz: np.ndarray | None) -> None:
        self._tones, self._fs, self._p, self._metric = tones, fs, coefficients, metric
        self._plant = plant
        self._f = (sensitivity.prediction_grid(tones, fs) if frequencies_hz is None
                   else np.asarray(frequencies_hz, dtype=float))
        self._g = np.asarray(plant(self._f), dtype=complex)

    def rise(self, rates: np.ndarray) -> tuple[float, float]:
        """(rise dB, at Hz); (inf, NaN) when the closed loop would be unstable."""
        if not sensitivity.closed_loop_is_stable(self._plant, self._tones, self._fs,
                                                 self._p, rates):
            return float('inf'), float('nan')
        k = sensitivity.canceller_frequency_response(self._tones, self._fs, self._p, rates,
                                                     self._f)
        s = sensitivity.sensitivity_matrix(self._g, k)
        if self._metric == 'sigma_max':
            mag = np.linalg.svd(s, compute_uv=False)[:, 0]
        else:
            mag = np.abs(sensitivity.strut_sensitivity(self._g, k)).max(axis=1)
        i = int(np.argmax(mag))
        return float(20.0 * np.log10(mag[i])), float(self._f[i])


def _largest_within(ok, lo: float, hi: float) -> float:
    """Largest x in [lo, hi] with ok(x), by bisection in log scale (ok(lo) assumed)."""
    if ok(hi):
        return hi
    for _ in range(BISECTION_STEPS):
        mid = float(np.sqrt(lo * hi))
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def choose_tone_rates(plant: sensitivity.PlantResponse,
                      tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
                      coefficients: np.ndarray, mu: float, policy: str = 'manual',
                      max_rise_db: float = DEFAULT_MAX_RISE_DB, metric: str = 'sigma_max',
                      frequencies_hz: np.ndarray | None = None) -> MuChoice:
    """Per-tone rates for ``policy`` and the rise they predict (see the module).

    Args:
        plant: callable frequencies (Hz) -> G (F, C, C) (the identified response's ``at``).
        tone_frequencies_hz: tones (Hz).
        sample_rate_hz: loop rate (Hz).
        coefficients: complex (T, C, C) normalised P_t (rate 1 = mu).
        mu: the set rate, the ceiling of every tone's rate.
        policy: ``manual`` or ``auto``.
        max_rise_db: limit of the predicted rise (dB, > 0).
        metric: ``sigma_max`` (default) or ``strut``.
        frequencies_hz: grid of the prediction (default
            :func:`~hexapod_vibration.core.control.sensitivity.prediction_grid`).

    Raises:
        ValueError: a bad policy, limit, metric, rate or tone list.
    """
    policy, limit = validate_policy(policy, max_rise_db)
    if metric not in ('sigma_max', 'strut'):
        raise ValueError(f"metric must be 'sigma_max' or 'strut', got {metric!r}")
    fs = float(sample_rate_hz)
    tones = validate_frequencies(tone_frequencies_hz, fs)
    p = np.asarray(coefficients, dtype=complex)
    rates = sensitivity.tone_rates(mu, tones.size)
    evaluator = _RiseEvaluator(plant, tones, fs, p, metric, frequencies_hz)
    mu = float(mu)
    if policy == 'auto' and mu > 0.0 and tones.size:
        rates = _auto_rates(evaluator, mu, tones.size, limit)
    rise_db, at_hz = evaluator.rise(rates) if tones.size else (0.0, float('nan'))
    warning = None
    if not np.isfinite(rise_db):
        warning = (f'the loop would be unstable with mu={mu:g} ({policy}): '
                   'lower mu or use mu_policy auto')
    elif rise_db > limit:
        warning = (f'mu={mu:g} predicts a rise of {rise_db:.1f} dB at {at_hz:.2f} Hz, '
                   f'above max_rise_db={limit:g} ({policy})')
    return MuChoice(policy, mu, rates, limit, rise_db, at_hz, metric, warning)


def _auto_rates(evaluator: _RiseEvaluator, mu: float, n_tones: int, limit: float
                ) -> np.ndarray:
    """Common scale first, then each tone raised alone (see the module)."""
    def ok(rates: np.ndarray) -> bool:
        return evaluator.rise(rates)[0] <= limit

    scale = _largest_within(lambda s: ok(np.full(n_tones, s * mu)), SMALLEST_SCALE, 1.0)
    rates = np.full(n_tones, scale * mu)
    if scale >= 1.0:
        return rates
    for t in range(n_tones):
        def ok_tone(x: float, t: int = t) -> bool:
            trial = rates.copy()
            trial[t] = x
            return ok(trial)
        rates[t] = _largest_within(ok_tone, rates[t], mu)
    return rates
