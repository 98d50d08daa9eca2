"""The driver's stand-in log: which due samples got a force no controller computed."""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.loop.command_arbiter import CommandArbiter
from hexapod_vibration.core.loop.stand_in_log import (
    LATE_WAIT_SAMPLES,
    STAND_IN_TOLERANCE_N,
    StandInLog,
)

F = np.full(6, 1.0)


def _run(log: StandInLog, last_due: int, late: dict[int, list[str]]) -> None:
    """Note ``late[due]`` streams' stand-ins (force F) and settle every due up to last_due."""
    for due in range(last_due + 1):
        for stream in late.get(due, []):
            log.note(due, stream, F)
        log.settle(due)


def test_a_right_stand_in_is_cleared_a_wrong_or_missing_one_reported():
    log = StandInLog()
    _run(log, 10, {3: ["pointing"], 5: ["pointing"], 7: ["notch"]})
    log.answered("pointing", 3, F + 0.5 * STAND_IN_TOLERANCE_N)       # the forecast was right
    log.answered("pointing", 5, F + 2.0 * STAND_IN_TOLERANCE_N)       # it was not
    log.answered("notch", 11, F)        # on time (not due yet): no stand-in of it pending
    _run(log, 10 + LATE_WAIT_SAMPLES, {})
    assert log.covered == 10
    assert log.drain() == [(5, 5, 0), (7, 7, 0)]                      # 7: never answered
    assert log.stood_in == 2 and log.drain() == []


def test_runs_merge_and_two_streams_at_one_sample_count_once():
    log = StandInLog()
    late = {4: ["notch", "pointing"], 5: ["pointing"], 6: ["notch"], 9: ["notch"]}
    _run(log, 9 + LATE_WAIT_SAMPLES, late)
    assert log.drain() == [(4, 6, 0), (9, 9, 0)] and log.stood_in == 4


def test_a_command_later_than_the_wait_leaves_the_stand_in_reported():
    log = StandInLog()
    _run(log, 2 + LATE_WAIT_SAMPLES, {2: ["pointing"]})
    log.answered("pointing", 2, F)                                     # too late: settled
    assert log.drain() == [(2, 2, 0)]


def test_the_arbiter_marks_late_connected_streams_that_got_a_stand_in():
    """Realtime: a late stream with a forecast row, a held command or zero force stood in.

    A stale one too (the watchdog's ramp to zero force: no controller computed it); not one
    that answered, nor any in lockstep.
    """
    arbiter = CommandArbiter(("notch", "pointing"), ("notch", "pointing"), run=1,
                             limit_n=100.0, delay_samples=0)
    for stream in arbiter.streams.values():
        stream.connected = True
    for n in range(3):
        arbiter.offer("notch", F, n, 1, 0.0)
        if n < 1:
            arbiter.offer("pointing", F, n, 1, 0.0)
        arbiter.close_sample(lockstep=False, timeout_samples=5)
        assert not arbiter.streams["notch"].stood_in
        assert arbiter.streams["pointing"].stood_in == (n >= 1)
        arbiter.advance()
    for _ in range(6):                                   # pointing silent beyond the timeout
        arbiter.close_sample(lockstep=False, timeout_samples=5)
        arbiter.advance()
    assert arbiter.streams["pointing"].stale and arbiter.streams["pointing"].stood_in
    arbiter.close_sample(lockstep=True, timeout_samples=50)
    assert not any(s.stood_in for s in arbiter.streams.values())


def test_a_run_with_the_watchdog_s_samples_is_marked():
    """The watchdog's samples (ramp, zero force) mark their run, whichever stream first."""
    log = StandInLog()
    for due in range(12):
        if due in (2, 3):
            log.note(due, "notch", F)                             # a forecast stood in
        if due in (3, 4, 5):
            log.note(due, "pointing", 0.5 * F, watchdog=True)     # the ramp, then zero
        if due == 8:
            log.note(due, "pointing", F, watchdog=True)
            log.note(due, "notch", F)
        if due == 10:
            log.note(due, "notch", F)
        log.settle(due + LATE_WAIT_SAMPLES)
    assert log.drain() == [(2, 5, 1), (8, 8, 1), (10, 10, 0)] and log.stood_in == 6
