"""A scenario's timeline against the notch's identification: what a run must not do.

The identification injects its own excitation (test tones or a broadband multisine) and
keeps the canceller frozen until it is done, so

- control-on inside it measures a canceller that has not started (or was refused: its
  reduction reads 0 dB), and
- an analysis window that overlaps it measures the excitation, not the disturbance.

The identification starts ``identify_at_s`` after the first sample and lasts what the
notch supervisor's own identifier takes for the point's settings
(:meth:`NotchSupervisor.start_identification` builds it; its ``duration_s`` is the length):
10 s for ``identification: broadband``, 3.2 s for one or two tones identified with test
tones. :func:`control_on_conflict` says why control cannot start when the scenario asks
(``experiment`` refuses such a scenario before it runs); :func:`timeline_conflict` says too
why a sweep point's windows cannot measure what they claim (a sweep refuses the grid; a
single run's report leaves the identification's samples out of its windows instead).
"""

from __future__ import annotations

from dataclasses import dataclass

from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor
from hexapod_vibration.core.sim.scenario import Scenario, notch_config


@dataclass(frozen=True)
class Interval:
    """A stretch of the run [start_s, stop_s) (s from the first sample)."""

    start_s: float
    stop_s: float

    def overlaps(self, other: Interval) -> bool:
        """True if the two stretches share any time."""
        return self.start_s < other.stop_s and other.start_s < self.stop_s

    def __str__(self) -> str:
        """``"0.5-10.5 s"``."""
        return f"{self.start_s:g}-{self.stop_s:g} s"


def identification_interval(scenario: Scenario, sample_rate_hz: float
                            ) -> tuple[Interval, str] | None:
    """When the start-up identification runs (s) and its method; None if there is none."""
    if not scenario.notch.tone_frequencies_hz:
        return None
    supervisor = NotchSupervisor(notch_config(scenario), sample_rate_hz)
    if not supervisor.config.auto_identify:
        return None
    supervisor.start_identification()
    start = scenario.identify_at_s
    return (Interval(start, start + supervisor.identification.identifier.duration_s),
            supervisor.config.identification)


def analysis_intervals(scenario: Scenario) -> dict[str, Interval]:
    """The report's two windows (s): before control-on, and the last ``window_s``."""
    on, end = scenario.control_on_s, scenario.duration_s
    return {"uncontrolled": Interval(on - scenario.window_s, on),
            "controlled": Interval(max(on, end - scenario.window_s), end)}


def _fix(scenario: Scenario, identification: Interval) -> str:
    """The control-on that leaves a whole uncontrolled window after the identification."""
    return (f"set control_on_s >= {identification.stop_s + scenario.window_s:g} s (the "
            f"{scenario.window_s:g} s uncontrolled window after it)")


def _control_on_inside(scenario: Scenario, found: tuple[Interval, str] | None) -> str | None:
    """Why control-on falls inside the identification ``found``, or None."""
    if found is None:
        return None
    identification, method = found
    on = scenario.control_on_s
    if identification.start_s <= on < identification.stop_s:
        return (f"control-on at {on:g} s falls inside the {method} identification "
                f"({identification}); {_fix(scenario, identification)}")
    return None


def control_on_conflict(scenario: Scenario, sample_rate_hz: float) -> str | None:
    """Why control cannot go on when the scenario asks (one line), or None if it can.

    Control-on inside the identification: the canceller is held until the identification
    ends and its analysis is done, so the run would measure no control at all.
    """
    return _control_on_inside(scenario, identification_interval(scenario, sample_rate_hz))


def timeline_conflict(scenario: Scenario, sample_rate_hz: float) -> str | None:
    """Why the point's timeline cannot measure control (one line), or None if it can."""
    found = identification_interval(scenario, sample_rate_hz)
    conflict = _control_on_inside(scenario, found)
    if conflict is not None or found is None:
        return conflict
    identification, method = found
    what = f"the {method} identification"
    for name, window in analysis_intervals(scenario).items():
        if window.overlaps(identification):
            return (f"the {name} window ({window}) overlaps {what} ({identification}); "
                    f"{_fix(scenario, identification)}")
    return None
