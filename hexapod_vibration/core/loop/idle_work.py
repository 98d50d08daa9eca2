"""Work no sample waits for, deferred by a loop callback and run when its loop is idle.

A controller's callback answers its sample and then has work that no deadline waits for:
every 10th sample a forecast of its next commands (``ros.command_forecasts``: 73-135 us
here). Run in the callback, that work delays whatever the thread does next; in the composed
graph (one process, one thread) that is the driver taking the sample's commands, so every
forecast sample's command latency grew by the forecast's cost and its parse (median 0.71-0.72
ms against 0.30-0.34 ms on the other samples, 42-45 % of them over 1 ms:
``docs/performance.md``).
The callback defers it instead (:meth:`IdleWork.defer`), and the loop's spinner
(``ros.executors.LoopSpinner``) runs it when the thread has nothing waiting: a wait without
timeout found no message, and the loop's owner says nothing is expected (the driver: every
command of the newest sample is in). Work that waited ``overdue_s`` runs at the next
opportunity whatever the loop is doing, so a loop that is never idle (overloaded) still
gets it, late.

A task runs once however often it is deferred before it runs (a forecast computed from the
state when it runs supersedes the ones asked for before). No ROS import.
"""

from __future__ import annotations

import time
from collections.abc import Callable

IDLE_OVERDUE_S = 0.005
"""Longest time (s, wall) deferred work waits for an idle loop before it runs anyway (five
1 kHz samples: a forecast covers the next 200)."""

Task = Callable[[], None]


class IdleWork:
    """Tasks deferred by a loop's callbacks, for its spinner to run when idle.

    Args:
        clock: Wall-clock seconds (tests pass a fake clock).
        overdue_s: A task deferred this long ago (s) is overdue (:meth:`overdue`).
    """

    def __init__(self, clock: Callable[[], float] = time.perf_counter,
                 overdue_s: float = IDLE_OVERDUE_S) -> None:
        """No task yet."""
        if overdue_s < 0.0:
            raise ValueError(f"overdue_s must be >= 0, got {overdue_s}")
        self._clock = clock
        self._overdue_s = overdue_s
        self._tasks: dict[Task, float] = {}     # task -> when first deferred (s)

    @property
    def pending(self) -> bool:
        """A task waits to run."""
        return bool(self._tasks)

    def defer(self, task: Task) -> None:
        """Run ``task()`` when the loop is idle; once, if it is deferred again meanwhile."""
        if task not in self._tasks:
            self._tasks[task] = self._clock()

    def overdue(self, now_s: float) -> bool:
        """The oldest task was deferred at least ``overdue_s`` before ``now_s`` (s)."""
        for deferred_s in self._tasks.values():        # insertion order: the oldest first
            return now_s - deferred_s >= self._overdue_s
        return False

    def run(self) -> int:
        """Run every pending task, oldest first; how many ran.

        A task deferred by one of them runs at the next call.
        """
        tasks, self._tasks = self._tasks, {}
        for task in tasks:
            task()
        return len(tasks)
