"""After an accepted identification: P and the bound at the oscillators, control on or refused.

:class:`ControlEngagement` puts what an identification measured in force, one piece per
sample (a generator driven by :class:`~.identification.PlantIdentification`): the
coefficients P of the adaptation mode at the oscillators' tones (from the measured G, or
from what is known at tones that moved meanwhile), the bound on ``mu`` (eq. 18 after a tone
identification; the Nyquist test on G(f), one test per piece and job, after a broadband
one), the clamp, and, after a broadband identification, the mu policy and the type-2 test.
A response unusable for the mode, or a bound of 0, refuses control with the reason.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.supervisor.analysis_jobs import Analysis
from hexapod_vibration.core.control.supervisor.parts import SupervisorParts


class ControlEngagement:
    """Puts a measured plant response in force at the oscillators (see the module)."""

    def __init__(self, parts: SupervisorParts) -> None:
        """The supervisor's collaborators it acts through."""
        self._parts = parts

    def engage(self, measured_tones: list[float], response: np.ndarray, broadband: bool
               ) -> Analysis:
        """Coefficients and bound at the oscillators; control on, or refused with why.

        ``response``: G (T, C, C) measured at ``measured_tones`` (Hz); the oscillators'
        tones now may differ (then what is known at them is used).
        """
        parts = self._parts
        canceller, rates, plant, gate = parts.canceller, parts.rates, parts.plant, parts.gate
        tones = [float(f) for f in canceller.tone_frequencies_hz]
        mode = parts.settings.config.adaptation
        current = response if tones == measured_tones else plant.known_response(tones)
        try:
            if current is None:
                raise ValueError(f"no identified response at {tones} Hz")
            if broadband:
                coefficients = adaptation.normalized_coefficients(current, mode)
            else:
                coefficients, bound = rates.coefficients_for(tones, current, mode)
        except ValueError as exc:
            gate.refuse(f"identification unusable for {mode}: {exc}; not adapting")
            return
        if broadband:
            bound = yield from rates.limit_steps(tones, coefficients)
        plant.put_in_force(current, tones)
        rates.bound = rates.mu_limit = bound
        canceller.set_coefficients(coefficients)
        gains = np.abs(np.diagonal(current, axis1=1, axis2=2)).mean(axis=1)
        source = "Nyquist on G(f)" if broadband else "eq. 18"
        parts.events.add("info", f"identified: |G_ii| {np.round(gains, 4)} (m/s^2)/N, "
                                 f"confidence {plant.confidence:.3f}, mu bound "
                                 f"{bound:.4g} ({source})")
        if bound <= 0.0:
            rates.clamp(0.0)
            gate.refuse(f"identified mu bound is 0 ({mode} adaptation at {tones} Hz): "
                              "no stable rate, control stays off")
            return
        gate.release()
        rates.clamp(bound)
        if broadband:
            yield
            yield from rates.choose_and_check(tones, coefficients)
        parts.follower.limit_bandwidth()
        parts.safety.restart()
        gate.resume()
        gate.started(parts.clock.last + 1)
