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
The rise is the largest ``20 log10 |S|`` over 0..fs/2 in the chosen view: by default
the output the report measures (the top plate's z axis) under the disturbance measured
before control, else the 6x6 loop's largest singular value (any disturbance direction).
The rise right beside a notch is set by the weight loop's phase there, not by the rate;
the rise far from the tones (where the plant is large, e.g. its resonances) scales with
the rates. So ``auto`` can only lower the second; when the first alone breaks the limit
it lowers the rates until the rest is within that floor plus :data:`FLOOR_MARGIN_DB`,
and says so (``single_tone_harmonic``: 1.0 dB beside the 80 Hz notch at any rate; keeping
mu there left the 18.7 Hz loop mode +1.7 dB over no control in its third octave).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.control import sensitivity
from hexapod_vibration.core.control.notch import validate_frequencies
from hexapod_vibration.parameter_specs import MU_POLICIES, NOTCH_CONTROLLER

DEFAULT_MAX_RISE_DB = NOTCH_CONTROLLER["max_rise_db"].default
"""The notch's default ``max_rise_db`` (dB)."""
RELATIVE_TOLERANCE = 0.02
SMALLEST_SCALE = 1e-3
FLOOR_MARGIN_DB = 0.1
"""When the rise beside a notch exceeds ``max_rise_db`` at any rate, ``auto`` bounds the
predicted rise to that floor plus this (dB) instead."""


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
        raise ValueError(f"mu_policy must be one of {MU_POLICIES}, got {policy!r}")
    value = float(max_rise_db)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"max_rise_db must be finite and > 0 dB, got {max_rise_db!r}")
    return policy, value


class _RiseEvaluator:
    """Predicted rise (dB) and stability for candidate per-tone rates.

    The grid follows the candidate rates (the notches' widths), so each evaluation
    builds it and evaluates G there.
    """

    def __init__(self, plant: sensitivity.PlantResponse, tones: np.ndarray, fs: float,
                 coefficients: np.ndarray, metric: str, output_weights: np.ndarray | None,
                 disturbance_csd: sensitivity.PlantResponse | None,
                 update_lowpass_hz: float = 0.0) -> None:
        self._tones, self._fs, self._p, self._metric = tones, fs, coefficients, metric
        self._plant, self._c, self._phi = plant, output_weights, disturbance_csd
        self._lowpass_hz = update_lowpass_hz

    def rise(self, rates: np.ndarray) -> tuple[float, float]:
        """(rise dB, at Hz); (inf, NaN) when the closed loop would be unstable."""
        prediction = sensitivity.predict_sensitivity(
            self._plant, self._tones, self._fs, self._p, rates,
            output_weights=self._c if self._metric == "output" else None,
            disturbance_csd=self._phi, update_lowpass_hz=self._lowpass_hz)
        return prediction.largest_rise(self._metric)


def _largest_within(ok, lo: float, hi: float) -> float:
    """Largest x in [lo, hi] with ok(x), to 2 %, by bisection in log scale (ok(lo) assumed)."""
    if ok(hi):
        return hi
    while hi > lo * (1.0 + RELATIVE_TOLERANCE):
        mid = float(np.sqrt(lo * hi))
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def choose_tone_rates(plant: sensitivity.PlantResponse,
                      tone_frequencies_hz: Sequence[float] | np.ndarray, sample_rate_hz: float,
                      coefficients: np.ndarray, mu: float, policy: str = "manual",
                      max_rise_db: float = DEFAULT_MAX_RISE_DB, metric: str | None = None,
                      output_weights: np.ndarray | None = None,
                      disturbance_csd: sensitivity.PlantResponse | None = None,
                      update_lowpass_hz: float = 0.0) -> MuChoice:
    """Per-tone rates for ``policy`` and the rise they predict (see the module).

    Args:
        plant: callable frequencies (Hz) -> G (F, C, C) (the identified response's ``at``).
        tone_frequencies_hz: tones (Hz).
        sample_rate_hz: loop rate (Hz).
        coefficients: complex (T, C, C) normalised P_t (rate 1 = mu).
        mu: the set rate, the ceiling of every tone's rate.
        policy: ``manual`` or ``auto``.
        max_rise_db: limit of the predicted rise (dB, > 0).
        metric: the view of S bounded: ``output`` (the output ``output_weights`` under the
            disturbance ``disturbance_csd``: what that output's spectrum will show; the
            default when both are given), ``sigma_max`` (any disturbance direction: the
            default otherwise) or ``strut``.
        output_weights: c (C,) of the output view (e.g. the z row of ``J^-1``).
        disturbance_csd: callable frequencies (Hz) -> CSD (F, C, C) of the error without
            control (e.g. ``DisturbanceSpectrum.at`` of the broadband identification).
        update_lowpass_hz: corner of the canceller's update low-pass (Hz; 0: none).

    Raises:
        ValueError: a bad policy, limit, metric, rate or tone list.
    """
    policy, limit = validate_policy(policy, max_rise_db)
    if metric is None:
        metric = ("output" if output_weights is not None and disturbance_csd is not None
                  else "sigma_max")
    if metric not in sensitivity.METRICS:
        raise ValueError(f"metric must be one of {sensitivity.METRICS}, got {metric!r}")
    if metric == "output" and output_weights is None:
        raise ValueError("metric 'output' needs output_weights")
    fs = float(sample_rate_hz)
    tones = validate_frequencies(tone_frequencies_hz, fs)
    p = np.asarray(coefficients, dtype=complex)
    rates = sensitivity.tone_rates(mu, tones.size)
    mu = float(mu)
    if tones.size == 0:
        return MuChoice(policy, mu, rates, limit, 0.0, float("nan"), metric, None)
    evaluator = _RiseEvaluator(plant, tones, fs, p, metric, output_weights, disturbance_csd,
                               update_lowpass_hz)
    floor_note = ""
    if policy == "auto" and mu > 0.0:
        rates, floor_note = _auto_rates(evaluator, mu, tones.size, limit)
    rise_db, at_hz = evaluator.rise(rates)
    warning = None
    if not np.isfinite(rise_db):
        warning = (f"the loop would be unstable with mu={mu:g} ({policy}): "
                   "lower mu or use mu_policy auto")
    elif rise_db > limit:
        warning = (f"mu={mu:g} predicts a rise of {rise_db:.1f} dB at {at_hz:.2f} Hz, "
                   f"above max_rise_db={limit:g} ({policy}{floor_note})")
    return MuChoice(policy, mu, rates, limit, rise_db, at_hz, metric, warning)


def _auto_rates(evaluator: _RiseEvaluator, mu: float, n_tones: int, limit: float
                ) -> tuple[np.ndarray, str]:
    """Common scale first, then each tone raised alone (see the module).

    The rise right beside a notch does not shrink with the rate (its height is set by the
    phase of the weight loop, its width by the rate), so a limit may be out of reach at
    any rate: then the rates are bounded to that floor plus :data:`FLOOR_MARGIN_DB`
    instead, and the returned note says why.
    """
    full = np.full(n_tones, mu)
    if evaluator.rise(full)[0] <= limit:
        return full, ""
    note = ""
    floor_db, floor_hz = evaluator.rise(full * SMALLEST_SCALE)
    if floor_db > limit:
        # the rise beside a notch stays whatever the rate: bound the rest (the far field,
        # e.g. a loop resonance the rates raise) to just above it instead of giving up
        limit = floor_db + FLOOR_MARGIN_DB
        note = (f"; {floor_db:.1f} dB at {floor_hz:.2f} Hz remain at any rate (a "
                f"coefficient phase error, not the rate): rates bounded to {limit:.2f} dB")

    def ok(rates: np.ndarray) -> bool:
        return evaluator.rise(rates)[0] <= limit

    if ok(full):
        return full, note
    scale = _largest_within(lambda s: ok(full * s), SMALLEST_SCALE, 1.0)
    rates = full * scale
    for t in range(n_tones):
        def ok_tone(x: float, t: int = t) -> bool:
            trial = rates.copy()
            trial[t] = x
            return ok(trial)
        rates[t] = _largest_within(ok_tone, rates[t], mu)
    return rates, note
