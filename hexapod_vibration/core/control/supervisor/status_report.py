"""What the notch supervisor reports: its state, the guard's, and its status values.

:class:`StatusReport` reads the supervisor's collaborators (nothing of its own), for
:class:`~hexapod_vibration.core.control.notch_supervisor.NotchSupervisor`'s ``state``,
``guard_state`` and ``status()`` (``/diagnostics``).
"""

from __future__ import annotations

from typing import Any

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control.supervisor.gate import BLIND_CONTROL
from hexapod_vibration.core.control.supervisor.identification import PlantIdentification
from hexapod_vibration.core.control.supervisor.parts import SupervisorParts
from hexapod_vibration.core.control.supervisor.plant_knowledge import coefficients_in_force


class StatusReport:
    """The supervisor's state names and status values, from its collaborators."""

    def __init__(self, parts: SupervisorParts, identification: PlantIdentification) -> None:
        """Read ``parts`` and ``identification`` when asked."""
        self._parts = parts
        self._identification = identification

    def state(self) -> str:
        """One of :class:`NotchState`'s names."""
        parts = self._parts
        return parts.gate.state(self._identification.busy,
                                coefficients_in_force(parts.plant, parts.canceller))

    def guard_state(self) -> str:
        """The guard's state: disabled, referencing, watching, backed_off or off."""
        parts = self._parts
        return parts.safety.state(parts.settings.config.divergence_guard,
                                  self.state() == NotchState.ADAPTING)

    def values(self) -> dict[str, Any]:
        """The controller's state as plain values, for ``/diagnostics``."""
        parts, identification = self._parts, self._identification
        cfg, canceller, gate, plant = (parts.settings.config, parts.canceller, parts.gate,
                                       parts.plant)
        values: dict[str, Any] = {
            "state": self.state(), "enabled": cfg.enabled,
            "enabled_since_sample": gate.enabled_since_sample,
            "last_sample": parts.clock.last, "mu": canceller.mu,
            "mu_bound": parts.rates.bound, "adaptation": cfg.adaptation,
            "tones_hz": [float(f) for f in canceller.tone_frequencies_hz],
            "identified_tones_hz": plant.tones,
            "identification_start_sample": identification.start_sample,
            "identification_end_sample": identification.end_sample,
            **parts.clock.counters}
        values.update(parts.follower.status())
        if gate.held:
            values["refusal"] = gate.reason
        elif gate.blind(identification.busy):
            values["not_adapting"] = BLIND_CONTROL
        values.update({"identification": cfg.identification,
                       "identification_confidence": round(plant.confidence, 4),
                       **parts.rates.status(), **parts.safety.status(self.guard_state())})
        values.update(plant.status())
        return values
