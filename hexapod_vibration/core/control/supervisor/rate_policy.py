"""The rate the canceller adapts at: coefficients P, the bound on mu, its clamp, the policy.

- P for the adaptation mode from the identified G at the oscillators
  (:func:`~hexapod_vibration.core.control.adaptation.normalized_coefficients`);
- the bound on ``mu``: eq. 18 with the loop delay, the smallest over the tones, after a tone
  identification; after a broadband one the largest common rate the Nyquist test finds
  stable on G(f) (eq. 18 is 15-50x optimistic on the PPH), one test per sample
  (:meth:`RatePolicy.limit_steps`); without G, the normalised modes' bound;
- a ``mu`` at or above the identified bound is lowered to half of it at once, and the
  divergence guard lowers it too: both are settings the supervisor changes itself
  (:meth:`RatePolicy.set_mu`, mirrored into the node's parameter);
- with G(f), ``mu_policy`` folds its per-tone rates into P and the predicted sensitivity
  |S(f)| is kept (:attr:`RatePolicy.sensitivity`);
- moving tones (tracking, a reference) sweep with a type-2 update
  (:data:`MOVING_TONE_INTEGRAL_RATIO`; :mod:`.sweep_gate` switches it on while a tone
  sweeps). The bound is the first-order update's, the one steady tones run; the type-2
  update is allowed only where the Nyquist test finds it stable at the rates in force
  (:meth:`RatePolicy.check_type2`). (The bound of the type-2 update is 0 at 39.0 Hz on the
  PPH, decentralized: a tracked tone told 40 Hz on a line at 39.0 Hz never engaged,
  though the first-order update it runs there is stable at every rate.)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod_vibration.core.control import adaptation, mu_policy, sensitivity
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.plant_identification import (
    DisturbanceSpectrum,
    PlantFrequencyResponse,
)
from hexapod_vibration.core.control.supervisor.analysis_jobs import (
    Analysis,
    Job,
    WaitingJobs,
    single_job,
)
from hexapod_vibration.core.control.supervisor.config import NotchConfig, Settings
from hexapod_vibration.core.control.supervisor.events import EventLog
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge
from hexapod_vibration.parameter_specs import moving_tones

MOVING_TONE_DAMPING = 0.7
"""Damping ratio of the type-2 weight update that moving tones (tracking or a reference)
adapt with (:meth:`AdaptiveNotchCanceller.set_integral_ratio`, ratio ``1 / (4 zeta^2)``).

A tone sweeping at a steady rate changes the disturbance it cancels (its path's response at
the tone's frequency, an amplitude growing with speed^2): the first-order update lags that
by its time constant, ``1/mu`` samples, and leaves the change over one time constant as the
residual. ``spin_up`` (core loop, tachometer, mu 0.006): the residual equals
``tau dD/dt`` (correlation 0.98-1.00); order 2 through the disturbance path's zero near 90
Hz changes by 24 %/s (z axis: a deeper minimum) and kept only 21 dB, order 3 at 93 Hz
18 dB (the identified G(f) is within 0.1 % of the model's there and -P G / 2 = I: neither
P nor the rate is the cause). The rate integrator removes the steady part of the change:
ramp (17-36 s) minimum 21 -> 41 dB on order 2 and 20 -> 33 dB on order 3 with the
tachometer, 21 -> 36 and 19 -> 30 dB tracked; 0.7 beat 1.0 and 1.5 on the averaged loop
driven by the recorded disturbance (order 3: 44, 35, 26 dB)."""
MOVING_TONE_INTEGRAL_RATIO = 1.0 / (4.0 * MOVING_TONE_DAMPING ** 2)


def moving_tone_integral_ratio(config: NotchConfig) -> float:
    """The type-2 ratio for sweeping tones (:data:`MOVING_TONE_INTEGRAL_RATIO`), or 0.

    Non-zero when the tones may move (tracking or a reference); 0: the paper's update.
    """
    moving = bool(config.tone_frequencies_hz) and moving_tones(vars(config))
    return MOVING_TONE_INTEGRAL_RATIO if moving else 0.0


def coefficients_and_bound(response: np.ndarray, mode: str,
                           delay_samples: float) -> tuple[np.ndarray, float]:
    """Adaptation coefficients P (T, C, C) for ``mode`` and the bound on ``mu``.

    The bound is eq. 18 with the loop delay (:func:`adaptation.mu_bound`) at every tone,
    the smallest over the tones: the rate must be stable at all of them.

    Args:
        response: identified plant response G (T, C, C), (m/s^2)/N.
        mode: one of :data:`~hexapod_vibration.parameter_specs.ADAPTATION_MODES`.
        delay_samples: loop delay beyond the one-sample command hold (samples).

    Raises:
        ValueError: G unusable for ``mode`` (ill-conditioned, zero diagonal, not finite).
    """
    coefficients = adaptation.normalized_coefficients(response, mode)
    bound = min(adaptation.mu_bound(g, c, delay_samples)
                for g, c in zip(response, coefficients, strict=True))
    return coefficients, float(bound)


def choose_and_predict(response: PlantFrequencyResponse, disturbance: DisturbanceSpectrum,
                       tones: list[float], sample_rate_hz: float, coefficients: np.ndarray,
                       mu: float, policy: str, max_rise_db: float,
                       output_weights: np.ndarray | None, update_lowpass_hz: float
                       ) -> tuple[mu_policy.MuChoice, np.ndarray,
                                  sensitivity.SensitivityPrediction]:
    """``mu_policy``'s per-tone rates, P (T, C, C) with them folded in, the predicted |S(f)|.

    A pure job of the analysis (:class:`RatePolicy.choose`): G(f) and the disturbance's
    spectrum of a broadband identification, the oscillators ``tones`` (Hz), normalised P,
    ``mu`` > 0, the policy and its largest rise (dB), the output c (None: sigma_max).
    """
    choice = mu_policy.choose_tone_rates(response.at, tones, sample_rate_hz, coefficients, mu,
                                         policy=policy, max_rise_db=max_rise_db,
                                         output_weights=output_weights,
                                         disturbance_csd=disturbance.at,
                                         update_lowpass_hz=update_lowpass_hz)
    folded = sensitivity.per_tone_coefficients(coefficients, mu, choice.tone_mu)
    prediction = sensitivity.predict_sensitivity(
        response.at, tones, sample_rate_hz, folded, mu, output_weights=output_weights,
        disturbance_csd=disturbance.at, check_stability=False,
        update_lowpass_hz=update_lowpass_hz)
    _ = prediction.sigma_max        # cached here, in the job: an SVD per frequency, ~36 ms
    return choice, folded, prediction


class RatePolicy:
    """P and the bound on mu from the identified plant; the mu policy and its prediction.

    Args:
        settings: the settings in force.
        canceller: the canceller whose mu and P are set.
        plant: what the identifications found.
        events: where the changes of ``mu`` are reported.
        output_weights: c (C,): the output whose rise ``mu_policy`` bounds and the
            prediction reports (``c^T e``); None: the 6x6 loop's largest singular value.
        waits: where a setting change's Nyquist limit and mu policy run (default inline).
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 plant: PlantKnowledge, events: EventLog,
                 output_weights: np.ndarray | None,
                 waits: WaitingJobs | None = None) -> None:
        """The normalised modes' bound until something is identified."""
        self.waits = waits or WaitingJobs()
        """How a setting change's computations run: inline, or on the analysis worker
        while the node serves its loop."""
        self._settings = settings
        self._canceller = canceller
        self._plant = plant
        self._events = events
        self._output_weights = output_weights
        self.bound = self.normalised_bound()
        """The bound on mu in force (``mu_bound`` on /diagnostics)."""
        self.mu_limit = float("nan")
        """The bound the last accepted identification gave."""
        self.choice: mu_policy.MuChoice | None = None
        """The mu policy's per-tone rates after a broadband identification, else None."""
        self.sensitivity: sensitivity.SensitivityPrediction | None = None
        """The predicted |S(f)| with those rates, else None."""
        self.type2_max_mu = float("inf")
        """The largest ``mu`` the type-2 update of sweeping tones is allowed at: the ``mu``
        the Nyquist test found it stable at, 0 where it found it unstable, inf untested
        (no G(f))."""
        self.unchosen: np.ndarray | None = None
        """Normalised P (T, C, C) in force without the policy's choice (it needs ``mu`` > 0,
        and new tones or a new mode bring a new P): :meth:`choose_pending` makes it."""
        self._last_limit: tuple[object, tuple, float] | None = None
        """(G(f), (tones, P bytes), limit) of the last Nyquist limit computed."""

    def normalised_bound(self) -> float:
        """The bound of a normalised mode (M = I) with the loop delay."""
        return adaptation.delayed_mode_mu_bound(1.0, self._settings.config.loop_delay_samples)

    def coefficients_for(self, tones: list[float], response: np.ndarray | None,
                         mode: str) -> tuple[np.ndarray | None, float]:
        """Coefficients for the canceller (None: new tones wait) and the mu bound."""
        if response is not None and self._plant.frequency_response is not None:
            coefficients = adaptation.normalized_coefficients(response, mode)
            return coefficients, self._nyquist_limit(tones, coefficients)
        if response is not None:
            return coefficients_and_bound(response, mode,
                                          self._settings.config.loop_delay_samples)
        if mode == "raw":
            channels = self._settings.channels
            identity = np.broadcast_to(np.eye(channels, dtype=complex),
                                       (len(tones), channels, channels))
            return (identity.copy() if tones else None), np.inf
        return None, self.normalised_bound()

    def _nyquist_limit(self, tones: list[float], coefficients: np.ndarray) -> float:
        """Largest common rate the Nyquist test finds stable on the identified G(f).

        The last one is kept: a parameter change is planned twice, when it is validated
        and when it is applied (~0.6 s of Nyquist tests each). It runs as :attr:`waits`
        says: inline, or on the analysis worker while the node serves its loop.
        """
        response = self._plant.frequency_response
        p = np.ascontiguousarray(coefficients)
        key = (tuple(tones), p.shape, p.tobytes())
        last = self._last_limit
        if last is not None and last[0] is response and last[1] == key:
            return last[2]
        limit = self.waits.run(single_job(Job(
            sensitivity.stable_mu_limit, (response.at, list(tones), self._settings.fs,
                                          p.copy()),
            {"update_lowpass_hz": self._settings.update_lowpass_hz})))
        self._last_limit = (response, key, limit)
        return limit

    def _stability_job(self, tones: list[float], coefficients: np.ndarray, mu: float,
                       integral_ratio: np.ndarray | float = 0.0) -> Job:
        """The Nyquist test on G(f) at the rate ``mu`` (:func:`closed_loop_is_stable`)."""
        return Job(sensitivity.closed_loop_is_stable,
                   (self._plant.frequency_response.at, list(tones), self._settings.fs,
                    np.array(coefficients), float(mu)),
                   {"integral_ratio": integral_ratio,
                    "update_lowpass_hz": self._settings.update_lowpass_hz})

    def limit_steps(self, tones: list[float], coefficients: np.ndarray) -> Analysis:
        """The Nyquist limit on G(f), one stability test (a job) per piece (a generator).

        As :func:`~hexapod_vibration.core.control.sensitivity.stable_mu_limit` (the
        largest stable common rate), found by doubling from 1e-5 and bisecting to 2 %, for
        the first-order update that steady tones run (the type-2 update of sweeping tones:
        :meth:`check_type2`).
        """
        def stable(mu: float) -> Job:
            return self._stability_job(tones, coefficients, mu)

        lo = 1e-5
        if not (yield stable(lo)):
            return 0.0
        hi = lo
        while True:
            yield
            hi = min(2.0 * hi, 1.0)
            if not (yield stable(hi)):
                break
            lo = hi
            if hi >= 1.0:
                return 1.0
        while hi > lo * 1.02:
            yield
            mid = float(np.sqrt(lo * hi))
            lo, hi = (mid, hi) if (yield stable(mid)) else (lo, mid)
        return lo

    def forget_choice(self) -> None:
        """A new identification: no policy result and no prediction until it is analysed."""
        self.sensitivity = self.choice = self.unchosen = None
        self.type2_max_mu = float("inf")

    def check_type2(self, tones: list[float]) -> Analysis:
        """Whether sweeping tones may adapt with the type-2 update (one Nyquist test).

        At the rates in force (the policy's, folded into P) with each tone's ratio
        :data:`MOVING_TONE_INTEGRAL_RATIO` ``mu_t / mu`` (:mod:`.sweep_gate`'s);
        :attr:`type2_max_mu` is ``mu`` if stable, else 0 (reported when the tones may move:
        they then sweep with the first-order update). A generator: one ``yield`` first.
        """
        canceller, cfg = self._canceller, self._settings.config
        mu = canceller.mu
        yield
        if not mu > 0.0:                    # nothing adapts: tested once mu is set
            self.type2_max_mu = 0.0
            return
        ratio = MOVING_TONE_INTEGRAL_RATIO * self.tone_rates() / mu
        stable = yield self._stability_job(tones, canceller.coefficients, mu, ratio)
        self.type2_max_mu = mu if stable else 0.0
        if not stable and moving_tone_integral_ratio(cfg) > 0.0:
            self._events.add("warn", f"the type-2 update of sweeping tones is unstable at "
                                     f"mu={mu:g} at {np.round(tones, 3).tolist()} Hz (Nyquist "
                                     "on G(f)): tones that sweep adapt with the first-order "
                                     "update")

    def choose(self, tones: list[float], coefficients: np.ndarray) -> Analysis:
        """Per-tone rates of ``mu_policy`` folded into P; the predicted sensitivity.

        The rates are shares of ``mu``: at ``mu`` 0 (nothing adapts) P goes in force as it
        is and the choice waits for a ``mu`` above 0 (:meth:`choose_pending`). The choice
        and the prediction are one job (:func:`choose_and_predict`).
        """
        cfg, mu = self._settings.config, self._canceller.mu
        if not mu > 0.0:
            self._canceller.set_coefficients(coefficients)
            self.defer(coefficients)
            self._events.add("info", "mu is 0: nothing adapts; the mu policy chooses the "
                                     "tones' rates once mu is set above 0")
            return
        self.unchosen = None
        choice, folded, self.sensitivity = yield Job(choose_and_predict, (
            self._plant.frequency_response, self._plant.disturbance, list(tones),
            self._settings.fs, np.array(coefficients), mu, cfg.mu_policy, cfg.max_rise_db,
            self._output_weights, self._settings.update_lowpass_hz))
        self.choice = choice
        self._canceller.set_coefficients(folded)
        self._events.add("warn" if choice.warning else "info",
                         choice.warning or f"mu_policy {choice.policy}: tone rates "
                         f"{np.round(choice.tone_mu, 6).tolist()}, predicted rise "
                         f"{choice.predicted_rise_db:.2f} dB at {choice.rise_at_hz:.2f} Hz")

    def defer(self, coefficients: np.ndarray) -> None:
        """Normalised P (T, C, C), in force at the canceller: the policy's choice made later."""
        self.choice = self.sensitivity = None
        self.unchosen = np.array(coefficients, dtype=complex)

    def choose_pending(self) -> None:
        """The policy's choice for a P put in force without one, once it can be made.

        With G(f) known and ``mu`` above 0 (a tone identification gives no G(f): then every
        tone adapts at ``mu``, as the policy ``manual``); then the type-2 test of sweeping
        tones (:meth:`check_type2`) at the rates chosen. Dropped if the oscillators changed.
        """
        pending = self.pending_choice()
        if pending is not None:
            self.waits.run(self.choose_and_check(*pending))

    def pending_choice(self) -> tuple[list[float], np.ndarray] | None:
        """(tones in Hz, normalised P) of the choice :meth:`choose_pending` would make, or None.

        None without G(f), at ``mu`` 0, or with nothing pending; a pending P that no longer
        fits the oscillators is dropped.
        """
        canceller, unchosen = self._canceller, self.unchosen
        if (unchosen is None or not canceller.mu > 0.0
                or self._plant.frequency_response is None):
            return None
        if unchosen.shape[0] != canceller.n_tones:
            self.unchosen = None
            return None
        return [float(f) for f in canceller.tone_frequencies_hz], unchosen

    def choose_and_check(self, tones: list[float], coefficients: np.ndarray) -> Analysis:
        """:meth:`choose`, then :meth:`check_type2` at the rates chosen (one analysis)."""
        yield from self.choose(tones, coefficients)
        yield from self.check_type2(tones)

    def tone_rates(self) -> np.ndarray:
        """Each oscillator's rate in force (1/sample): the policy's, scaled to ``mu`` now.

        The policy's per-tone rates (folded into P) follow ``mu`` when it changes (the guard
        lowers it); without a policy's choice every oscillator adapts at ``mu``.
        """
        choice, mu = self._choice_in_force(), self._canceller.mu
        if choice is None:
            return np.full(self._canceller.n_tones, mu)
        return choice.tone_mu * (mu / choice.mu)

    def tone_rate_scale(self) -> np.ndarray | float:
        """Each oscillator's rate relative to ``mu`` (1.0: every oscillator at ``mu``).

        The policy's per-tone rates folded into P, so that the sweep gate gives every
        tone's type-2 loop the same damping (``kappa_t = R mu_t``).
        """
        choice = self._choice_in_force()
        return 1.0 if choice is None else choice.tone_mu / choice.mu

    def _choice_in_force(self) -> mu_policy.MuChoice | None:
        """The policy's choice if it fits the oscillators now (a rate per tone, mu > 0)."""
        choice = self.choice
        if (choice is None or choice.tone_mu.shape != (self._canceller.n_tones,)
                or not choice.mu > 0.0):
            return None
        return choice

    def clamp(self, bound: float) -> None:
        """Lower ``mu`` to half the bound (0 for a bound of 0) if it is not below it."""
        mu = self._canceller.mu
        if mu < bound or mu == 0.0:
            return
        clamped = 0.5 * bound
        self.set_mu(clamped, f"mu={mu:g} is outside the identified stability bound "
                             f"{bound:.4g}: clamped to {clamped:.4g}")

    def set_mu(self, mu: float, reason: str) -> None:
        """The supervisor sets ``mu`` itself: in force, in the settings, reported (warn).

        The event carries the new value for the node to mirror into its parameter.
        """
        self._canceller.set_mu(mu)
        self._settings.set_mu(mu)
        self._events.add("warn", reason, ("mu", mu))

    def status(self) -> dict[str, Any]:
        """The bound found, the policy and its rates, the predicted rise (for /diagnostics)."""
        choice = self.choice
        rise, at_hz = ((choice.predicted_rise_db, choice.rise_at_hz) if choice is not None
                       else (float("nan"), float("nan")))
        return {"mu_limit": self.mu_limit, "mu_policy": self._settings.config.mu_policy,
                "update_lowpass_hz": self._settings.update_lowpass_hz,
                "tone_mu": ([] if choice is None else np.round(choice.tone_mu, 8).tolist()),
                "predicted_rise_db": round(float(rise), 3),
                "predicted_rise_at_hz": round(float(at_hz), 3)}
