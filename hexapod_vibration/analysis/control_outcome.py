"""What control did in a run, from the notch controller's ``/diagnostics`` in the bag.

A report states first whether the control the run asked for was in force in its controlled
window, and if not, why: refused (the identification was unusable or gave no stable rate),
faded out (the safety monitor found it making things worse), backed off (the guard lowered
its rate) or never switched on. No ROS import: the statuses are the key/value texts the bag
holds (``state``, ``refusal``, ``not_adapting``, ``guard``, ``guard_action``,
``last_sample``, ``enabled``).

``report.json`` gets a ``control`` block::

    {"asked": bool, "engaged": bool, "engaged_at_sample": int | None,
     "in_force": bool,              # adapting over the whole controlled window
     "outcome": "controlled" | "backed_off" | "faded" | "refused" | "interrupted"
                | "never_engaged" | "not_asked" | "unknown",
     "reason": str, "sample": int | None}

``sample`` is the first sample at which the notch reported the outcome (a refusal, a fade,
a back-off); ``reason`` its own words.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

from hexapod_vibration.contract import NotchState

GUARD_BACKED_OFF = "backed_off"
GUARD_OFF = "off"


@dataclass(frozen=True)
class ControlOutcome:
    """The ``control`` block of a report (see the module docstring)."""

    asked: bool
    engaged: bool
    engaged_at_sample: int | None
    in_force: bool
    outcome: str
    reason: str = ""
    sample: int | None = None

    def as_dict(self) -> dict:
        """The block as plain values, for ``report.json``."""
        return asdict(self)

    def headline(self) -> str:
        """One line that says what happened, '' when control was in force as asked."""
        at = "" if self.sample is None else f" at sample {self.sample}"
        texts = {
            "refused": f"CONTROL REFUSED{at}: {self.reason}",
            "faded": f"CONTROL FADED OUT{at}: {self.reason}",
            "backed_off": f"CONTROL BACKED OFF{at}: {self.reason}",
            "interrupted": f"CONTROL INTERRUPTED{at}: {self.reason}",
            "unknown": f"CONTROL UNKNOWN: {self.reason}",
            "never_engaged": "CONTROL NEVER ENGAGED: the notch did not adapt after control-on"
                             + (f" ({self.reason})" if self.reason else ""),
        }
        text = texts.get(self.outcome, "")
        if text and not self.in_force:
            text += "; the reductions below are not those of control"
        return text


def control_outcome(statuses: Sequence[dict[str, str]], control_on_sample: int | None,
                    window_start: int | None, notch_tones: bool) -> ControlOutcome:
    """The outcome of a run from the notch's statuses, oldest first.

    Args:
        statuses: the notch's ``/diagnostics`` values over the run.
        control_on_sample: the sample control was switched on (None: never).
        window_start: the first sample of the controlled window (None: no window).
        notch_tones: whether the run had notch tones (control to ask for).
    """
    if not statuses:
        asked = control_on_sample is not None or notch_tones
        return ControlOutcome(asked, False, None, False, "unknown" if asked else "not_asked",
                              "no notch status in the bag" if asked else "")
    if not notch_tones:
        return ControlOutcome(False, False, None, False, "not_asked")
    asked = control_on_sample is not None or any(s.get("enabled") == "true" for s in statuses)
    engaged_at = _first(statuses, lambda s: s.get("state") == NotchState.ADAPTING)
    refused = _first_status(statuses, lambda s: s.get("state") == NotchState.REFUSED)
    backed = _first_status(statuses, lambda s: s.get("guard") == GUARD_BACKED_OFF)
    start = window_start if window_start is not None else control_on_sample
    after = [s for s in statuses if start is None or _sample(s) >= start]
    adapting_throughout = bool(after) and all(s.get("state") == NotchState.ADAPTING
                                              for s in after)
    if not asked:
        return ControlOutcome(False, engaged_at is not None, engaged_at, False, "not_asked")
    if refused is not None:
        faded = engaged_at is not None and engaged_at <= _sample(refused)
        return ControlOutcome(asked, engaged_at is not None, engaged_at, False,
                              "faded" if faded else "refused", refused.get("refusal", ""),
                              _sample(refused))
    if engaged_at is None:
        last = statuses[-1]
        return ControlOutcome(True, False, None, False, "never_engaged",
                              last.get("not_adapting")
                              or f"its last state: {last.get('state', '?')}")
    if backed is not None:
        return ControlOutcome(True, True, engaged_at, adapting_throughout, "backed_off",
                              backed.get("guard_action", ""), _sample(backed))
    if adapting_throughout:
        return ControlOutcome(True, True, engaged_at, True, "controlled")
    if not after:
        return ControlOutcome(True, True, engaged_at, False, "unknown",
                              f"no notch status in the controlled window (its last at "
                              f"sample {_sample(statuses[-1])})")
    stopped = _first_status(after, lambda s: s.get("state") != NotchState.ADAPTING)
    return ControlOutcome(True, True, engaged_at, False, "interrupted",
                          f"state {stopped.get('state', '?')} in the controlled window",
                          _sample(stopped))


def _sample(status: dict[str, str]) -> int:
    try:
        return int(status.get("last_sample", "-1"))
    except ValueError:
        return -1


def _first_status(statuses, predicate) -> dict[str, str] | None:
    return next((s for s in statuses if predicate(s)), None)


def _first(statuses, predicate) -> int | None:
    status = _first_status(statuses, predicate)
    return None if status is None else _sample(status)
