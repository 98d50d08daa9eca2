"""A set of setting changes, checked as a whole (:mod:`.planning`) and put in force.

:class:`SettingsChange` is the supervisor's ``check`` and ``apply``: the new settings, ``mu``
(only a different value is the user's new choice: the node mirrors a mu the supervisor
lowered back into it), new oscillators or a new adaptation mode with their P and bound, the
safety monitor's retry, control switched on or off, the identification retargeted, the tone
follower rebuilt, and the mu policy's choice for a P put in force without one (now, or
on the analysis worker while the loop runs: :mod:`.background_choice`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from hexapod_vibration.core.control.supervisor.background_choice import BackgroundChoice
from hexapod_vibration.core.control.supervisor.identification import PlantIdentification
from hexapod_vibration.core.control.supervisor.parts import SupervisorParts
from hexapod_vibration.core.control.supervisor.planning import Plan, plan_changes
from hexapod_vibration.core.control.supervisor.tone_follower import (
    FOLLOW_SETTINGS,
)
from hexapod_vibration.parameter_specs import moving_tones


class SettingsChange:
    """Checks and applies sets of setting changes (see the module)."""

    def __init__(self, parts: SupervisorParts, identification: PlantIdentification,
                 choice: BackgroundChoice) -> None:
        """The supervisor's collaborators the changes act through."""
        self._choice = choice
        self._settings, self._canceller, self._clock = (parts.settings, parts.canceller,
            parts.clock)
        self._plant, self._rates, self._gate = parts.plant, parts.rates, parts.gate
        self._safety, self._follower = parts.safety, parts.follower
        self._identification = identification

    def plan(self, changes: Mapping[str, Any]) -> Plan:
        """What ``changes`` lead to, checked as a whole; nothing changed.

        Raises KeyError (not a notch setting) or ValueError (the reason, one line).
        """
        return plan_changes(self._settings, changes, self._canceller.mu, self._plant,
                            self._rates)

    def apply(self, changes: Mapping[str, Any]) -> None:
        """Apply ``changes`` (refused as :meth:`plan` would say, nothing changed).

        The plan is made inline (the check before it usually left its Nyquist limit to
        reuse): the loop must not run between the plan and the state it changes.
        """
        with self._rates.waits.inline():
            plan = self.plan(changes)
        self._choice.cancel()           # a choice in progress: made again below if pending
        canceller, settings = self._canceller, self._settings
        identification = self._identification
        settings.config = plan.config
        new_mu = "mu" in changes and float(changes["mu"]) != canceller.mu
        if "mu" in changes:
            canceller.set_mu(changes["mu"])
        tones_changed = "tone_frequencies_hz" in changes or "harmonics" in changes
        mode_changed = "adaptation" in changes
        self._safety.apply(changes, plan.tones if tones_changed else None)
        if tones_changed or mode_changed or new_mu:
            self._safety.retry(identification.busy)
        if tones_changed:
            canceller.set_tone_frequencies(plan.tones, coefficients=plan.coefficients,
                                           ramp_samples=settings.ramp_samples)
        elif mode_changed and plan.coefficients is not None:
            canceller.set_coefficients(plan.coefficients)
        if (tones_changed or mode_changed) and plan.response is not None:
            self._rates.defer(plan.coefficients)       # the policy chooses again, below
        self._plant.put_in_force(plan.response, plan.tones)
        self._rates.bound = plan.bound
        if "enabled" in changes:
            self._gate.switch(bool(changes["enabled"]), identification.busy,
                              self._clock.last + 1)
        if tones_changed or mode_changed:
            identification.retarget(plan, mode_changed)
        if tones_changed or any(name in changes for name in FOLLOW_SETTINGS):
            self._follower.rebuild()
        if not identification.busy:
            self._choice.choose_pending(steady=not moving_tones(vars(plan.config)))
