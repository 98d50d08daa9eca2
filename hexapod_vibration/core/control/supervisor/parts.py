"""The notch supervisor's shared collaborators, handed as one to those that use them all."""

from __future__ import annotations

from dataclasses import dataclass

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.events import EventLog
from hexapod_vibration.core.control.supervisor.gate import ControlGate
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge
from hexapod_vibration.core.control.supervisor.rate_policy import RatePolicy
from hexapod_vibration.core.control.supervisor.safety import SafetyMonitor
from hexapod_vibration.core.control.supervisor.sample_clock import SampleClock
from hexapod_vibration.core.control.supervisor.tone_follower import ToneFollower


@dataclass(frozen=True)
class SupervisorParts:
    """The settings in force, the canceller and the collaborators around them.

    For :class:`~.identification.PlantIdentification`,
    :class:`~.engagement.ControlEngagement` and :class:`~.settings_change.SettingsChange`,
    which act through all of them.
    """

    settings: Settings
    canceller: AdaptiveNotchCanceller
    clock: SampleClock
    """The samples taken (an identification's span, the next sample)."""
    plant: PlantKnowledge
    rates: RatePolicy
    gate: ControlGate
    safety: SafetyMonitor
    follower: ToneFollower
    events: EventLog
