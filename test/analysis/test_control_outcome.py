"""What control did, from the notch's statuses: the report's control block and headline."""

from __future__ import annotations

from hexapod_vibration.analysis.control_outcome import control_outcome
from hexapod_vibration.analysis.report_tables import control_headline


def status(sample: int, state: str, **more: str) -> dict[str, str]:
    return {"last_sample": str(sample), "state": state, "enabled": "true", **more}


IDENTIFYING = [status(1000, "disabled"), status(5000, "identifying")]


def test_control_in_force_through_the_window():
    statuses = [*IDENTIFYING, status(12000, "adapting"), status(20000, "adapting")]
    outcome = control_outcome(statuses, 12000, 14000, True)
    assert (outcome.outcome, outcome.engaged, outcome.in_force) == ("controlled", True, True)
    assert outcome.engaged_at_sample == 12000 and outcome.headline() == ""


def test_a_refused_identification_is_said_first_with_its_reason_and_sample():
    reason = "identification refused: 2309 of its 8000 measured samples (28.9 %) missing"
    statuses = [*IDENTIFYING, status(10999, "refused", refusal=reason),
                status(20000, "refused", refusal=reason)]
    outcome = control_outcome(statuses, 12000, 14000, True)
    assert (outcome.outcome, outcome.engaged, outcome.in_force) == ("refused", False, False)
    assert (outcome.reason, outcome.sample) == (reason, 10999)
    report = {"control": outcome.as_dict()}
    assert control_headline(report) == (f"CONTROL REFUSED at sample 10999: {reason}; the "
                                        "reductions below are not those of control")


def test_a_fade_after_control_engaged_is_a_fade():
    why = "divergence guard: 1/3 octave 200 Hz +2.4 dB over its level without control"
    statuses = [*IDENTIFYING, status(12000, "adapting"), status(22499, "refused", refusal=why)]
    outcome = control_outcome(statuses, 12000, 14000, True)
    assert (outcome.outcome, outcome.engaged, outcome.in_force) == ("faded", True, False)
    assert outcome.sample == 22499 and outcome.headline().startswith("CONTROL FADED OUT")


def test_a_back_off_keeps_control_in_force_and_is_reported():
    statuses = [*IDENTIFYING, status(12000, "adapting"),
                status(15000, "adapting", guard="backed_off", guard_action="mu / 4 at 20 Hz")]
    outcome = control_outcome(statuses, 12000, 14000, True)
    assert (outcome.outcome, outcome.in_force, outcome.reason) == ("backed_off", True,
                                                                   "mu / 4 at 20 Hz")
    assert control_headline({"control": outcome.as_dict()}) == (
        "CONTROL BACKED OFF at sample 15000: mu / 4 at 20 Hz")


def test_never_engaged_interrupted_and_not_asked():
    never = control_outcome([*IDENTIFYING, status(20000, "identifying")], 12000, 14000, True)
    assert never.outcome == "never_engaged" and not never.engaged
    cut = control_outcome([*IDENTIFYING, status(12000, "adapting"),
                           status(16000, "disabled")], 12000, 14000, True)
    assert (cut.outcome, cut.in_force, cut.sample) == ("interrupted", False, 16000)
    assert control_outcome([], None, None, False).outcome == "not_asked"
    twin = [status(1000, "disabled", enabled="false"), status(9000, "disabled",
                                                                enabled="false")]
    assert control_outcome(twin, None, 14000, True).outcome == "not_asked"


def test_never_engaged_quotes_why_the_notch_could_not_adapt():
    why = "control on but not adapting: the plant at the tones is not identified (...)"
    statuses = [status(1000, "enabled", not_adapting=why), status(20000, "enabled",
                                                                   not_adapting=why)]
    outcome = control_outcome(statuses, 12000, 14000, True)
    assert (outcome.outcome, outcome.reason) == ("never_engaged", why)
    assert outcome.headline() == ("CONTROL NEVER ENGAGED: the notch did not adapt after "
                                  f"control-on ({why}); the reductions below are not those "
                                  "of control")


def test_no_status_in_the_controlled_window_is_unknown_not_a_crash():
    """The notch's last status came before the window (seen in a realtime run's bag)."""
    statuses = [*IDENTIFYING, status(12000, "adapting")]
    outcome = control_outcome(statuses, 12000, 14000, True)
    assert (outcome.outcome, outcome.engaged, outcome.in_force) == ("unknown", True, False)
    assert outcome.headline() == ("CONTROL UNKNOWN: no notch status in the controlled window "
                                  "(its last at sample 12000); the reductions below are not "
                                  "those of control")
    empty = control_outcome([], 12000, 14000, True)
    assert empty.outcome == "unknown" and "CONTROL UNKNOWN" in empty.headline()
