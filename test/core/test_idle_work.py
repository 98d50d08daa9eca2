"""IdleWork (core/loop/idle_work.py): deferred once, run oldest first, overdue by its clock."""

import pytest

from hexapod_vibration.core.loop.idle_work import IDLE_OVERDUE_S, IdleWork


class Clock:
    """A wall clock the test moves (s)."""

    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


def test_a_task_deferred_twice_runs_once_and_tasks_run_oldest_first():
    work, ran = IdleWork(Clock()), []
    first, second = (lambda: ran.append("first")), (lambda: ran.append("second"))
    assert not work.pending and work.run() == 0
    work.defer(first)
    work.defer(second)
    work.defer(first)
    assert work.pending
    assert work.run() == 2 and ran == ["first", "second"]
    assert not work.pending and work.run() == 0 and ran == ["first", "second"]


def test_the_oldest_task_is_overdue_from_its_first_deferral():
    clock = Clock()
    work = IdleWork(clock)
    assert not work.overdue(clock.now_s + 1.0)                   # nothing pending
    work.defer(list)
    clock.now_s += 0.5 * IDLE_OVERDUE_S
    work.defer(list)                         # deferred again: still due since the first
    work.defer(dict)
    assert not work.overdue(100.0 + 0.99 * IDLE_OVERDUE_S)
    assert work.overdue(100.0 + 1.01 * IDLE_OVERDUE_S)
    work.run()
    assert not work.overdue(clock.now_s + 1.0)


def test_a_task_deferred_by_a_running_task_runs_at_the_next_call():
    work, ran = IdleWork(Clock()), []

    def again() -> None:
        ran.append("again")

    def first() -> None:
        ran.append("first")
        work.defer(again)

    work.defer(first)
    assert work.run() == 1 and ran == ["first"] and work.pending
    assert work.run() == 1 and ran == ["first", "again"]


def test_a_negative_overdue_time_is_refused():
    with pytest.raises(ValueError, match="overdue_s"):
        IdleWork(overdue_s=-0.001)
