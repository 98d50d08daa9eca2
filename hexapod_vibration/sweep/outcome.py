"""What control did in a point's run: the point's status, and the reason when it is not ok.

A point asks for settings (a ``mu``, a mode); the notch supervisor may run something else
and says so. The status says which, so that a map never shows a number for a setting that
did not run:

- ``ok``: control ran at the requested rate through the run;
- ``clamped``: control ran, at a lower rate than requested: the supervisor lowered ``mu``
  to half its identified bound (a ``mu`` at or above the bound), or its ``mu_policy`` gave
  a tone a lower rate;
- ``backed_off``: the divergence guard lowered ``mu`` (control made a band worse than off)
  and control went on at the lower rate;
- ``faded``: control ran, then faded out (the divergence guard at any rate, or a line off
  the notch), and was off at the end;
- ``refused``: control never engaged (the identification failed, or no stable rate);
- ``failed``: the point raised (its error in the table).

``backed_off`` (a column) is whether the guard lowered ``mu`` during the run, also when it
faded out afterwards; None without a supervisor.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control.divergence_guard import GUARD_BACKED_OFF, GUARD_OFF
from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor
from hexapod_vibration.core.sim.closed_loop import LoopRecord

OK, CLAMPED, BACKED_OFF, FADED, REFUSED, FAILED = (
    "ok", "clamped", "backed_off", "faded", "refused", "failed")
STATUSES = (OK, CLAMPED, BACKED_OFF, FADED, REFUSED, FAILED)
RAN_OTHER_RATE = (CLAMPED, BACKED_OFF)
"""Control ran, at another rate than requested: the values are measured, at that rate."""
NOT_CONTROLLED = (FADED, REFUSED, FAILED)
"""No controlled window to measure: the map shows the status only."""
RELATIVE_TOLERANCE = 1e-9


def control_outcome(supervisor: NotchSupervisor | None, record: LoopRecord,
                    requested_mu: float) -> dict[str, Any]:
    """``status``, ``control_note`` (the reason, one line), ``backed_off``, the rates.

    ``mu_in_force`` is the supervisor's mu at the end of the run, ``tone_mu`` the rate of
    each tone (its ``mu_policy``; mu for every tone without a broadband identification),
    ``predicted_rise_db`` the largest rise off the tones it predicted for them (dB; None
    without a broadband identification).
    """
    if supervisor is None:
        return {"status": OK, "control_note": None, "backed_off": None,
                "mu_in_force": None, "tone_mu": [], "predicted_rise_db": None}
    status = supervisor.status()
    guard = status["guard"]
    lowered = guard == GUARD_BACKED_OFF or (guard == GUARD_OFF
                                            and supervisor.safety.guard.action_count > 1)
    rates = [float(r) for r in status["tone_mu"]] or [float(status["mu"])]
    out: dict[str, Any] = {"backed_off": bool(lowered), "mu_in_force": float(status["mu"]),
                           "tone_mu": rates, "control_note": None,
                           "predicted_rise_db": _finite(status["predicted_rise_db"])}
    refusal = status.get("refusal", "")
    if status["state"] == NotchState.REFUSED and refusal:
        engaged = _engaged(record, int(status["identification_end_sample"]))
        out.update(status=FADED if engaged else REFUSED, control_note=refusal)
    elif guard == GUARD_BACKED_OFF:
        out.update(status=BACKED_OFF, control_note=f"divergence guard: "
                                                   f"{status['guard_action']}")
    elif min(rates) < requested_mu * (1.0 - RELATIVE_TOLERANCE):
        out.update(status=CLAMPED, control_note=(
            f"mu {requested_mu:g} ran at {_rates(rates)} (identified bound "
            f"{float(status['mu_bound']):.4g}, mu_policy {status['mu_policy']})"))
    else:
        out["status"] = OK
    return out


def _engaged(record: LoopRecord, identification_end: int) -> bool:
    """Whether the canceller gave any output after its identification."""
    return bool(np.any(record.notch_command_n[identification_end + 1:] != 0.0))


def _finite(value: Any) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def _rates(rates: list[float]) -> str:
    return ", ".join(f"{r:.4g}" for r in rates)
