"""An identification a stall of the loop disturbed starts again once the platform settled.

``supervisor/stall_restart.py`` alone, and through the notch supervisor on the static rig
(``test/static_rig.py``): the driver's stand-in reports (command delay 0) mark a run of its
watchdog inside the broadband identification's record.
"""

import numpy as np
from static_rig import TONE, coupled_gain, run

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control.guard_feed import WATCHDOG_SETTLE_SAMPLES
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.control.supervisor.stall_restart import (
    MAX_STALL_RESTARTS,
    StallRestart,
)

START = 100                                     # identify_delay_s 0.1


def test_a_run_disturbs_the_record_it_overlaps_with_its_settling():
    assert StallRestart.disturbs(5_000, 8_000, 1_000, 10_000)
    assert StallRestart.disturbs(500, 1_500, 1_000, 10_000)      # settling into the start
    assert not StallRestart.disturbs(200, 1_000, 1_000, 10_000)  # settled before it
    assert not StallRestart.disturbs(11_000, 14_000, 1_000, 10_000)   # after the record


def test_restarts_are_counted_and_limited():
    stall = StallRestart()
    for k in range(MAX_STALL_RESTARTS):
        assert stall.schedule(1_000 * (k + 1)) and stall.waiting
        assert not stall.due(1_000 * (k + 1) - 1) and stall.due(1_000 * (k + 1))
        assert not stall.waiting
    assert not stall.schedule(9_000) and not stall.waiting and stall.restarts == 0


def _identifying() -> NotchSupervisor:
    sup = NotchSupervisor(NotchConfig().replaced(
        {"tone_frequencies_hz": (TONE,), "enabled": True, "identify_delay_s": 0.1}))
    run(sup, coupled_gain(0.0), START + 10)
    assert sup.identification.running and sup.identification.start_sample == START
    return sup


def _stall(sup: NotchSupervisor, first: int, last: int) -> None:
    """The driver's report: its watchdog's run over due samples first..last."""
    sup.note_stand_ins([(first, last, 1)], last + 20, 0)


def test_a_stall_in_the_record_restarts_the_identification_after_the_settling():
    sup = _identifying()
    run(sup, coupled_gain(0.0), 4_000, START + 10)
    _stall(sup, 3_000, 3_400)
    settled = 3_400 + WATCHDOG_SETTLE_SAMPLES
    assert sup.state == NotchState.IDENTIFYING and not sup.identification.running
    status = sup.status()                                 # the span its excitation ran
    assert (status["identification_start_sample"], status["identification_end_sample"]) == (
        START, START + 4_009)
    events = [e.message for e in sup.drain_events()]
    assert any(f"starts again at sample {settled}" in e for e in events), events
    run(sup, coupled_gain(0.0), settled - (START + 4_010), START + 4_010)
    assert not sup.identification.running                        # still settling
    run(sup, coupled_gain(0.0), 1, settled)
    assert sup.identification.running and sup.identification.start_sample == settled
    run(sup, coupled_gain(0.0), 10_000 + 2_000, settled + 1)     # the whole record again
    assert sup.state == NotchState.ADAPTING, [e.message for e in sup.drain_events()]
    np.testing.assert_allclose(np.abs(np.diagonal(sup.plant_response[0])), 0.1, rtol=0.05)


def test_a_stall_while_settling_puts_the_restart_later_without_counting_one():
    sup = _identifying()
    run(sup, coupled_gain(0.0), 1_000, START + 10)
    _stall(sup, 900, 1_000)
    _stall(sup, 1_500, 1_600)                                    # while it waits
    stall = sup.identification.stall
    assert stall.resume_at == 1_600 + WATCHDOG_SETTLE_SAMPLES and stall.restarts == 1


def test_a_loop_that_keeps_stalling_is_refused_with_the_reason():
    sup = _identifying()
    n = START + 10
    for _ in range(MAX_STALL_RESTARTS + 1):
        run(sup, coupled_gain(0.0), 1_000, n)
        n += 1_000
        _stall(sup, n - 500, n - 400)
        if sup.state == NotchState.REFUSED:
            break
        n = sup.identification.stall.resume_at
        run(sup, coupled_gain(0.0), 1, n)
        n += 1
    assert sup.state == NotchState.REFUSED
    events = [e.message for e in sup.drain_events()]
    assert any(f"stalled in its record {MAX_STALL_RESTARTS + 1} times" in e
               for e in events), events
