"""Executor choice for the 1 kHz nodes, and the loop spinner that serves their hot path.

Each node has a read-only ``executor`` parameter:

- ``waitset`` (the default): the node's 1 kHz loop subscriptions are served from one
  persistent rcl wait set and taken directly and serialized (``take_message``: no
  conversion to a Python message, which costs about 19 us per message here), every queued
  message at each wake-up; their callbacks get the CDR bytes (loop subscriptions are raw:
  ``messages.create_loop_subscription``); everything else (parameter services,
  ``~/identify``, graph events) is served by a SingleThreadedExecutor every
  ``SERVICE_PERIOD_S``, when the loop is idle (within ``IDLE_OVERDUE_S`` after, whatever it
  does), as is the work the nodes' callbacks deferred (:mod:`~hexapod_vibration.core.loop.
  idle_work`: the forecasts), so neither delays a sample's commands. rclpy's executors
  rebuild a wait set from every entity of the node and go through a task per callback on
  every spin. Measured on the project's 2-core machine: a ping-pong between two processes
  takes 388 us per round trip with the executor and 222 us with a wait set; the notch
  controller's CPU per 1 kHz sample fell from 656 to 288 us (docs/performance.md has the
  loop as a whole).
- ``single_threaded``: rclpy's SingleThreadedExecutor for everything.
- ``events``: rclpy's experimental EventsExecutor (Jazzy), for comparison only: on this
  machine it misses more samples than ``waitset`` in realtime and does not stop on SIGINT
  (``make bench``; it stalled while a 1 kHz ``/clock`` subscriber was in its process).

All three run in the node's one thread: a parameter change is never applied in the middle
of a sample's computation. The persistent wait set and the direct take are rclpy internals
(:mod:`hexapod_vibration.ros.rclpy_internals`): where they are not verified, ``waitset``
falls back to the executor's own ``spin_once``.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.subscription import Subscription

from hexapod_vibration.core.loop.cost_meter import LoopCostMeter
from hexapod_vibration.core.loop.idle_work import IDLE_OVERDUE_S, IdleWork
from hexapod_vibration.parameter_specs import EXECUTOR, EXECUTORS
from hexapod_vibration.ros.parameters import declare_string
from hexapod_vibration.ros.rclpy_internals import (
    RCL_ERRORS,
    LoopWaitSet,
    fast_path,
    take_serialized,
)

DEFAULT_EXECUTOR = EXECUTOR.default
SERVICE_PERIOD_S = 0.05
"""Time (s, wall) between two services of the non-loop callbacks by ``waitset`` (the next
idle moment after it, at most ``IDLE_OVERDUE_S`` later).

One service (an executor ``spin_once`` over every entity of the process's nodes) costs
0.2-0.4 ms here; every 50 ms that is under 1 % of the loop, and ``ros2 param set`` is
answered within 55 ms."""
IDLE_SPIN_S = 0.01
"""Longest single wait (s) of a node's main loop, so shutdown is noticed promptly."""


_LOOP_METER = LoopCostMeter()


def loop_meter() -> LoopCostMeter:
    """The CPU budget meter of this process's loop thread.

    One per process: composed nodes share it, so its stages and totals are the process's.
    """
    return _LOOP_METER


def declare_executor_parameter(node: Node) -> str:
    """Declare the read-only ``executor`` parameter (``parameter_specs.EXECUTOR``) alone.

    For a node not declared from a ``NodeSpec`` yet; a spec'd node has it in its spec.
    """
    return declare_string(node, EXECUTOR.name, EXECUTOR.default, EXECUTOR.description,
                          EXECUTOR.choices, read_only=True)


def make_executor(name: str) -> Executor:
    """Create the rclpy executor behind ``name`` (one of :data:`EXECUTORS`)."""
    if name in ("waitset", "single_threaded"):
        return SingleThreadedExecutor()
    if name == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    raise ValueError(f"executor must be one of {EXECUTORS}, got {name!r}")


class LoopSpinner:
    """``spin_once`` for a node with 1 kHz loop subscriptions (see the module docstring).

    With ``fast=False`` (or where rclpy's internals are not verified) it is the executor's
    own ``spin_once``. With ``fast=True`` the loop subscriptions are waited on in a
    persistent wait set and their callbacks are called directly with the serialized
    message (bytes), in arrival order per subscription; the executor serves the rest (and
    calls the same callbacks if it takes a loop message itself: bytes too, the loop
    subscriptions being raw).
    """

    def __init__(self, executor: Executor, subscriptions: Sequence[Subscription],
                 fast: bool, service_period_s: float = SERVICE_PERIOD_S,
                 latest_only: Sequence[Subscription] = (),
                 skipped: Mapping[Subscription, Callable[[bytes], None]] | None = None,
                 answered: int = 1, idle_work: Sequence[IdleWork] = ()) -> None:
        """Bind to ``executor`` (which holds the node) and its loop ``subscriptions``.

        ``latest_only``: subscriptions (among ``subscriptions``) whose callback gets only the
        newest ``answered`` of the messages queued at a wake-up, oldest first, the older
        ones taken and dropped. A controller that fell behind (a realtime loop after a
        stall) answers the samples the driver can still apply instead of working through
        samples whose deadlines passed: what it skipped is a gap in its sequence, counted
        as missed samples. A driver with ``command_delay_samples`` d applies the answer to
        sample m when it steps m + d: while m + d is the newest sample published, m is
        still in time, so a controller answers d + 1 (the node's own
        ``command_delay_samples`` + 1, :func:`~hexapod_vibration.ros.node_runner.run_node`).
        ``skipped``: for some of those, a callable that gets each skipped (older) message,
        oldest first, before the callback gets the newest (e.g. to record a sample it will
        not answer).
        ``idle_work``: the nodes' deferred work (:mod:`~hexapod_vibration.core.loop.
        idle_work`), run when the loop is idle (:meth:`spin_once`).
        """
        self.executor = executor
        self.subscriptions = list(subscriptions)
        self._latest_only = frozenset(latest_only)
        self._skipped = dict(skipped or {})
        self._answered = max(int(answered), 1)
        self._newest: deque[bytes] = deque()
        self.fast = fast and bool(self.subscriptions) and fast_path()
        self.service_period_s = service_period_s
        self.meter = loop_meter()
        self._wait_stage = self.meter.stage("wait")
        self._take_stage = self.meter.stage("take")
        self._service_stage = self.meter.stage("service")
        self._idle_stage = self.meter.stage("idle work")
        self._idle_work = list(idle_work)
        self._served_s = 0.0
        self._wait_set = None
        if self.fast:
            self._wait_set = LoopWaitSet(executor.context, self.subscriptions)

    def spin_once(self, timeout_sec: float, idle: bool | Callable[[], bool] = True) -> None:
        """Dispatch ready callbacks, waiting up to ``timeout_sec`` (s) for a loop message.

        Work that no sample waits for runs when the loop is idle: the executor's service of
        the non-loop callbacks (every ``service_period_s``) and the nodes' deferred work.
        Idle is ``idle`` (or what it returns: the loop's owner expects no message now; asked
        only when such work is due) and a wait without timeout finding no message; the
        call then returns without waiting. Work overdue by ``IDLE_OVERDUE_S`` runs whatever
        the loop is doing.
        """
        if not self.fast:
            self.executor.spin_once(timeout_sec=timeout_sec)
            self.meter.lap(self._service_stage)
            if self._work_pending() and (self._work_overdue(time.perf_counter())
                                         or _asked(idle)):
                self._run_idle_work()
            return
        now = time.perf_counter()
        since_service_s = now - self._served_s
        service = since_service_s >= self.service_period_s
        if service or self._work_pending():
            overdue = (since_service_s >= self.service_period_s + IDLE_OVERDUE_S
                       or self._work_overdue(now))
            if not overdue:
                if not _asked(idle):
                    self._serve_ready(timeout_sec)
                    return
                if self._serve_ready(0.0):
                    return                 # messages first: the caller looks at them
            if service:
                self._served_s = now
                self.executor.spin_once(timeout_sec=0.0)
                self.meter.lap(self._service_stage)
            self._run_idle_work()
            # The executor may have taken a loop message (its callback ran): no wait, so
            # the caller sees it rather than waiting for the next one.
            timeout_sec = 0.0
        self._serve_ready(timeout_sec)

    def _work_pending(self) -> bool:
        return any(work.pending for work in self._idle_work)

    def _work_overdue(self, now: float) -> bool:
        return any(work.overdue(now) for work in self._idle_work)

    def _run_idle_work(self) -> None:
        for work in self._idle_work:
            work.run()
        self.meter.lap(self._idle_stage)

    def serve_loop(self, timeout_sec: float) -> None:
        """The loop subscriptions' callbacks, waiting up to ``timeout_sec`` (s) for one.

        Then the nodes' deferred work if no message came (or it is overdue). Not the
        executor: this is for a callback of it that waits (a parameter change's computation
        on a worker) while the loop keeps its deadline; the executor's other work waits
        with it. Fast path only (``fast``).
        """
        served = self._serve_ready(timeout_sec)
        if self._work_pending() and (not served or self._work_overdue(time.perf_counter())):
            self._run_idle_work()

    def _serve_ready(self, timeout_sec: float) -> bool:
        """Serve the loop subscriptions ready within ``timeout_sec`` (s); whether any was."""
        ready = self._wait(max(timeout_sec, 0.0))
        for sub in ready:
            self._take_all_of(sub)
        return bool(ready)

    def _wait(self, timeout_sec: float) -> list[Subscription]:
        """The loop subscriptions with data, waiting up to ``timeout_sec`` for one.

        Only a wait that found nothing asks whether the context is shut down (a lock and a
        call, ~1 us, several times a sample). After one that found data the messages are
        taken (a take still succeeds on a shut-down context) and their callbacks run: a
        publish then fails (``RCL_ERRORS``, handled as the end), and every loop asks
        ``rclpy.ok()`` once a sample.
        """
        try:
            ready = self._wait_set.wait(timeout_sec)
        except RCL_ERRORS:
            self._raise_if_shut_down()
            raise
        self.meter.lap(self._wait_stage)
        if not ready:
            self._raise_if_shut_down()
        return ready

    def _take_all_of(self, sub: Subscription) -> None:
        """Take every queued message of ``sub``; call its callback with each (or the newest)."""
        if sub in self._latest_only:
            newest = self._newest          # one buffer for every wake-up, empty between
            newest.clear()
            on_skipped = self._skipped.get(sub)
            while (raw := self._take(sub)) is not None:
                if len(newest) == self._answered:
                    oldest = newest.popleft()
                    if on_skipped is not None:
                        on_skipped(oldest)
                newest.append(raw)
            while newest:
                sub.callback(newest.popleft())
            return
        while (raw := self._take(sub)) is not None:
            sub.callback(raw)

    def _take(self, sub: Subscription) -> bytes | None:
        """One serialized message of ``sub``, or None if none is queued."""
        try:
            raw = take_serialized(sub)
            self.meter.lap(self._take_stage)
            return raw
        except RCL_ERRORS:
            # rclpy's executors treat a failing take after shutdown (Ctrl-C) as the end.
            self._raise_if_shut_down()
            raise

    def _raise_if_shut_down(self) -> None:
        if not self.executor.context.ok():
            raise ExternalShutdownException()


def _asked(idle: bool | Callable[[], bool]) -> bool:
    return idle() if callable(idle) else idle


def spin_loop(node: Node, spinner: LoopSpinner) -> None:
    """Serve ``node`` until shutdown (the main loop of a controller node)."""
    while rclpy.ok():
        spinner.spin_once(IDLE_SPIN_S)
