"""The driver's command pairing and watchdog (core/loop/command_arbiter.py), without ROS.

The rules the node tests check through processes (test/nodes/test_watchdog.py), here exact
and per call: one command per sample (the first valid one), refusals by reason, the
watchdog's hold and drop, lockstep's waited streams, missed and late counts.
"""

import numpy as np
import pytest

from hexapod_vibration.core.loop.command_arbiter import (
    NO_FORCE_N,
    CommandArbiter,
    Refusal,
)

RUN = 42
TIMEOUT = 5
LIMIT_N = 70.0


def _arbiter(expected=("notch", "pointing")) -> CommandArbiter:
    arbiter = CommandArbiter(("notch", "pointing"), expected, RUN, LIMIT_N, "notch")
    arbiter.refresh_connections({"notch": 1, "pointing": 1}, TIMEOUT)
    return arbiter


def _force(value: float) -> np.ndarray:
    return np.full(6, value)


def _step(arbiter, lockstep=True):
    forces, stale = arbiter.close_sample(lockstep, TIMEOUT)
    arbiter.advance()
    return forces, stale


def test_first_valid_command_per_sample_is_applied():
    arbiter = _arbiter()
    assert arbiter.offer("notch", _force(1.0), 0, RUN, 0.0) is None
    assert arbiter.offer("notch", _force(2.0), 0, RUN, 0.0) is Refusal.DUPLICATE
    assert arbiter.offer("pointing", _force(3.0), None, None, 0.0) is None
    assert arbiter.ready(TIMEOUT)
    forces, _ = _step(arbiter)
    np.testing.assert_array_equal(forces["notch"], _force(1.0))
    np.testing.assert_array_equal(forces["pointing"], _force(3.0))
    assert arbiter.streams["notch"].refused[Refusal.DUPLICATE] == 1
    assert arbiter.streams["notch"].invalid == 0


def test_late_duplicate_for_the_previous_sample_is_not_applied_now():
    """Regression: a second command for n-1 arriving at n replaced the first and was held."""
    arbiter = _arbiter(expected=("pointing",))
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    _step(arbiter)
    # sample 1: the notch's command for 1 is late; a duplicate for 0 arrives first
    assert arbiter.offer("notch", _force(9.0), 0, RUN, 0.0) is Refusal.DUPLICATE
    forces, _ = _step(arbiter)
    np.testing.assert_array_equal(forces["notch"], _force(1.0))     # held, not 9 N


def test_late_first_command_is_held_as_the_latest():
    """A command whose sample was passed (after a timeout) is still the freshest one."""
    arbiter = _arbiter(expected=("pointing",))
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    _step(arbiter)
    _step(arbiter)
    assert arbiter.offer("notch", _force(2.0), 1, RUN, 0.0) is None
    assert arbiter.offer("notch", _force(3.0), 0, RUN, 0.0) is Refusal.OUT_OF_ORDER
    forces, _ = _step(arbiter)
    np.testing.assert_array_equal(forces["notch"], _force(2.0))


@pytest.mark.parametrize("values, index, run, reason", [
    (_force(70.5), 0, RUN, Refusal.OUT_OF_RANGE),
    (np.array([0, 0, 0, 0, 0, -1e300]), 0, RUN, Refusal.OUT_OF_RANGE),
    (_force(1.0), 0, RUN + 1, Refusal.OTHER_RUN),
    (_force(1.0), 1, RUN, Refusal.FUTURE),
    (_force(1.0), 10**9, None, Refusal.FUTURE),
])
def test_refused_commands_are_counted_and_never_applied(values, index, run, reason):
    arbiter = _arbiter(expected=())
    assert arbiter.offer("notch", values, index, run, 0.0) is reason
    assert arbiter.streams["notch"].refused[reason] == 1
    assert arbiter.streams["notch"].invalid == 1
    forces, _ = _step(arbiter)
    assert forces["notch"] is NO_FORCE_N
    values, warn, _ = arbiter.report(1.0, lockstep=True)
    assert values[f"notch_{reason}"] == 1 and values["notch_invalid"] == 1 and warn


def test_command_at_the_actuator_limit_is_accepted():
    arbiter = _arbiter(expected=())
    assert arbiter.offer("notch", _force(-LIMIT_N), 0, RUN, 0.0) is None


def test_watchdog_holds_then_drops_after_the_timeout():
    arbiter = _arbiter(expected=())
    arbiter.offer("notch", _force(4.0), 0, RUN, 0.0)
    held, events = [], []
    for _ in range(TIMEOUT + 3):
        forces, stale = _step(arbiter)
        held.append(float(forces["notch"][0]))
        events += stale
    assert held == [4.0] * (TIMEOUT + 1) + [0.0] * 2
    assert events == ["notch"] and arbiter.streams["notch"].stale_events == 1
    values, warn, message = arbiter.report(1.0, lockstep=True)
    assert "notch" in message and warn


def test_lockstep_waits_for_fresh_connected_expected_streams_only():
    arbiter = _arbiter(expected=("notch",))
    assert arbiter.waited(TIMEOUT) == []                 # never commanded: not fresh
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    assert arbiter.ready(TIMEOUT)
    _step(arbiter)
    assert arbiter.waited(TIMEOUT) == ["notch"] and not arbiter.ready(TIMEOUT)
    for _ in range(TIMEOUT):
        _step(arbiter)
    assert arbiter.waited(TIMEOUT) == [] and arbiter.ready(TIMEOUT)   # dropped: not waited
    assert arbiter.stats.missed == TIMEOUT         # samples 1..5 unanswered


def test_a_late_answer_makes_a_dropped_stream_waited_again():
    """A restarted controller first answers samples the loop has passed (its queue)."""
    arbiter = _arbiter(expected=("notch",))
    for _ in range(60):
        _step(arbiter)
    assert arbiter.waited(TIMEOUT) == []
    assert arbiter.offer("notch", _force(1.0), 10, RUN, 0.0) is None   # 50 samples late
    assert not arbiter.fresh("notch", TIMEOUT)
    assert arbiter.waited(TIMEOUT) == ["notch"] and not arbiter.ready(TIMEOUT)
    forces, _ = _step(arbiter)
    assert forces["notch"] is NO_FORCE_N                 # too old to apply: watchdog
    assert arbiter.offer("notch", _force(2.0), 61, RUN, 0.0) is None
    assert arbiter.ready(TIMEOUT)


def test_handshake_waits_for_every_expected_stream():
    arbiter = _arbiter()
    assert arbiter.unanswered() == ["notch", "pointing"]
    arbiter.offer("pointing", _force(0.0), 0, RUN, 0.0)
    assert arbiter.unanswered() == ["notch"]


def test_realtime_counts_late_streams():
    arbiter = _arbiter()
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    _step(arbiter, lockstep=False)
    assert arbiter.stats.late_commands == 1
    assert (arbiter.streams["notch"].late, arbiter.streams["pointing"].late) == (0, 1)
    values, _, _ = arbiter.report(1.0, lockstep=False)
    assert values["missed_samples"] == 1


def test_a_joining_stream_counts_from_its_first_command_not_the_next_graph_look():
    """A stream is connected from its first accepted command.

    Regression: a controller that joined between two looks at the graph (every 200
    samples) had its late answers uncounted, and no stand-in marked, until the next look.
    """
    arbiter = CommandArbiter(("notch", "pointing"), (), RUN, LIMIT_N, "notch")
    arbiter.refresh_connections({}, TIMEOUT)            # nobody on the graph yet
    _step(arbiter, lockstep=False)
    assert arbiter.stats.late_commands == 0             # not connected: not late
    assert arbiter.offer("pointing", _force(1.0), 1, RUN, 0.0) is None
    _step(arbiter, lockstep=False)                      # sample 1: answered
    _step(arbiter, lockstep=False)                      # sample 2: late, held
    pointing = arbiter.streams["pointing"]
    assert pointing.connected and pointing.late == 1 and pointing.stood_in
    assert arbiter.streams["notch"].late == 0


def test_latency_and_period_from_the_given_times():
    arbiter = _arbiter()
    arbiter.published(10.000)
    arbiter.offer("notch", _force(1.0), 0, RUN, 10.002)
    arbiter.offer("pointing", _force(1.0), 0, RUN, 10.009)
    _step(arbiter)
    arbiter.published(10.005)
    values, _, _ = arbiter.report(11.0, lockstep=False)
    assert (arbiter.stats.latencies_ms.count, arbiter.stats.periods_ms.count) == (1, 1)
    assert (values["latency_ms_max"], values["period_ms_max"]) == pytest.approx((2.0, 5.0))
    assert 2.0 <= values["latency_ms_p99"] <= 2.0101 and 5.0 <= values["period_ms_p50"] <= 5.0101


def test_a_breakpoint_is_neither_loop_time_nor_a_period():
    """Held 100 s between two samples 1 ms apart: rate 2 samples / 2 ms, period 1 ms."""
    arbiter = _arbiter()
    arbiter.restart_stats(10.000)
    arbiter.published(10.000)
    _step(arbiter)
    arbiter.pause(10.001)
    assert arbiter.report(50.0, lockstep=False)[0]["rate_hz"] == pytest.approx(1000.0)
    arbiter.resume(110.001)
    arbiter.published(110.001)
    _step(arbiter)
    values, _, _ = arbiter.report(110.002, lockstep=False)
    assert values["rate_hz"] == pytest.approx(1000.0)
    assert values["period_ms_max"] == pytest.approx(1.0)


def test_unknown_expected_stream_is_refused():
    with pytest.raises(ValueError, match="unknown"):
        CommandArbiter(("notch", "pointing"), ("other",), RUN, LIMIT_N)


def test_duplicates_do_not_warn():
    arbiter = _arbiter()
    for name in ("notch", "pointing"):
        arbiter.offer(name, _force(1.0), 0, RUN, 0.0)
        arbiter.offer(name, _force(1.0), 0, RUN, 0.0)
    _step(arbiter)
    values, warn, message = arbiter.report(1.0, lockstep=True)
    assert values["notch_duplicate"] == 1 and not warn and message == "ok"


def _delayed(delay: int) -> CommandArbiter:
    arbiter = CommandArbiter(("notch", "pointing"), ("notch",), RUN, LIMIT_N, "notch",
                             delay_samples=delay)
    arbiter.refresh_connections({"notch": 1}, TIMEOUT)
    return arbiter


def test_with_a_command_delay_the_answer_to_n_is_applied_at_n_plus_d():
    arbiter = _delayed(2)
    applied = []
    for n in range(6):
        assert arbiter.due == n - 2
        arbiter.offer("notch", _force(n + 1.0), n, RUN, 0.0)
        forces, _ = _step(arbiter, lockstep=False)
        applied.append(forces["notch"][0])
    assert applied == [0.0, 0.0, 1.0, 2.0, 3.0, 4.0]
    assert arbiter.stats.late_commands == 0                  # nothing due at 0 and 1
    assert arbiter.streams["notch"].late == 0


def test_a_command_delay_gives_a_late_answer_its_extra_periods():
    """Delay 1: an answer to n that comes during n+1 is on time; one that comes later is held."""
    arbiter = _delayed(1)
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    _step(arbiter, lockstep=False)                            # 0: nothing due
    _step(arbiter, lockstep=False)                            # 1: answer 0 applied
    arbiter.offer("notch", _force(2.0), 1, RUN, 0.0)          # answer 1 came during 2
    forces, _ = _step(arbiter, lockstep=False)
    assert forces["notch"][0] == 2.0 and arbiter.streams["notch"].late == 0
    forces, _ = _step(arbiter, lockstep=False)                # 3: answer 2 never came
    assert forces["notch"][0] == 2.0 and arbiter.streams["notch"].late == 1
    arbiter.offer("notch", _force(4.0), 3, RUN, 0.0)          # the controller skipped to 3
    arbiter.offer("notch", _force(5.0), 4, RUN, 0.0)          # and answered 4 early
    forces, _ = _step(arbiter, lockstep=False)                # 4: answer 3 due
    assert forces["notch"][0] == 4.0 and arbiter.streams["notch"].late == 1
    forces, _ = _step(arbiter, lockstep=False)                # 5: answer 4 due
    assert forces["notch"][0] == 5.0


def test_lockstep_with_a_command_delay_waits_for_the_sample_due():
    arbiter = _delayed(1)
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    assert arbiter.ready(TIMEOUT)
    _step(arbiter)
    assert arbiter.ready(TIMEOUT)                             # answer 0 is due: here
    forces, _ = _step(arbiter)
    assert forces["notch"][0] == 1.0 and arbiter.stats.missed == 0
    assert not arbiter.ready(TIMEOUT)                         # answer 1 is due: missing


def test_the_loop_is_idle_once_every_waited_stream_answered_the_newest_sample():
    """Realtime with a delay: the sample due is in long before; idle waits for the newest."""
    arbiter = _delayed(1)
    _step(arbiter, lockstep=False)                            # now at sample 1
    arbiter.offer("notch", _force(1.0), 0, RUN, 0.0)
    assert arbiter.ready(TIMEOUT) and not arbiter.answered(TIMEOUT)
    arbiter.offer("pointing", _force(2.0), 1, RUN, 0.0)       # not expected: not waited
    assert not arbiter.answered(TIMEOUT)
    arbiter.offer("notch", _force(3.0), 1, RUN, 0.0)
    assert arbiter.answered(TIMEOUT)
    _step(arbiter, lockstep=False)
    assert arbiter.ready(TIMEOUT) and not arbiter.answered(TIMEOUT)


@pytest.mark.parametrize("delay", [-1, 1.5])
def test_a_command_delay_is_a_whole_number_of_samples(delay):
    with pytest.raises(ValueError, match="delay_samples"):
        _delayed(delay)


def test_the_held_log_has_the_runs_the_arbiter_held():
    from hexapod_vibration.core.loop.held_log import HeldLog

    arbiter, log = _delayed(1), HeldLog()
    answered = {0, 1, 2, 5, 6, 14, 15}
    for n in range(17):
        if n in answered:
            arbiter.offer("notch", _force(n + 1.0), n, RUN, 0.0)
        arbiter.close_sample(False, TIMEOUT)
        stream = arbiter.streams["notch"]
        log.note(arbiter.due, stream.applied, stream.fade.gain)
        arbiter.advance()
    # due 3, 4: the answer to 2 stood in; due 7..10: that of 6; at samples 12 and 13 (due
    # 11, 12) the newest answer (6) was more than 5 samples old: zero force; at sample 14
    # the answer to 14 made the stream fresh again, and the answer to 6 stood in for 13.
    assert log.drain() == [(3, 4, 2, 1.0), (7, 10, 6, 1.0), (11, 12, 6, 0.0),
                           (13, 13, 6, 1.0)]
    assert log.covered == 15 and log.drain() == []


def test_a_stale_stream_falls_to_zero_force_along_the_ramp_and_rises_back():
    """The watchdog's ramp: gain times the held command down, gain times the new up."""
    from hexapod_vibration.core.loop.held_log import HeldLog

    fade = 8
    arbiter, log = _arbiter(expected=()), HeldLog()
    arbiter.offer("notch", _force(4.0), 0, RUN, 0.0)
    applied = []
    for n in range(40):
        if n >= 30:
            arbiter.offer("notch", _force(2.0), n, RUN, 0.0)
        forces, _ = arbiter.close_sample(False, TIMEOUT, fade)
        log.note(arbiter.due, arbiter.streams["notch"].applied,
                 arbiter.streams["notch"].fade.gain)
        applied.append(float(forces["notch"][0]))
        arbiter.advance()
    held, fall = applied[:TIMEOUT + 1], np.array(applied[TIMEOUT + 1:TIMEOUT + 1 + fade])
    assert held == [4.0] * (TIMEOUT + 1)
    assert np.all(np.diff(fall) < 0) and 0.0 < fall[-2] and fall[0] < 4.0
    assert applied[TIMEOUT + fade:30] == [0.0] * (30 - TIMEOUT - fade)   # fully down
    rise = np.array(applied[30:30 + fade])
    assert np.all(np.diff(rise) > 0) and rise[0] > 0.0 and applied[30 + fade - 1:] == [2.0] * (
        40 - 30 - fade + 1)
    # the ramp is symmetric: rising on 2 N it passes the gains it fell through on 4 N
    np.testing.assert_allclose(rise[:-1] / 2.0, fall[::-1][1:] / 4.0)
    # the held log: held at full gain, one row per sample of the fall, zero, the rise
    rows = log.drain()
    assert rows[0] == (1, TIMEOUT, 0, 1.0)
    fall_rows = rows[1:fade]
    assert [row[:3] for row in fall_rows] == [(n, n, 0) for n in range(TIMEOUT + 1,
                                                                     TIMEOUT + fade)]
    np.testing.assert_allclose([row[3] * 4.0 for row in fall_rows], fall[:-1])
    assert rows[fade] == (TIMEOUT + fade, 29, 0, 0.0)
    assert [row[:3] for row in rows[fade + 1:]] == [(n, n, n) for n in range(30, 30 + fade - 1)]
    np.testing.assert_allclose([row[3] * 2.0 for row in rows[fade + 1:]], rise[:-1])


def test_a_stall_shorter_than_the_ramp_turns_back_where_it_is():
    fade = 100
    arbiter = _arbiter(expected=())
    applied = []
    for n in range(400):
        if n < 50 or n >= 80:                    # 30 samples silent: 55..79 stale
            arbiter.offer("notch", _force(1.0), n, RUN, 0.0)
        applied.append(float(_step_faded(arbiter, fade)["notch"][0]))
    low = min(applied)
    assert 0.0 < low < 1.0 and applied.index(low) == 79     # the lowest: the last stale one
    assert applied[103] < 1.0 and applied[104:] == [1.0] * (400 - 104)   # 25 samples up


def _step_faded(arbiter, fade):
    forces, _ = arbiter.close_sample(False, TIMEOUT, fade)
    arbiter.advance()
    return forces
