"""The recorder's loop: everything queued taken at most every ``BATCH_PERIOD_S``, written.

At SIGINT/SIGTERM what is still queued is written before the bag is closed. The signal
handler only sets a plain attribute (:class:`StopFlag`): a handler that takes a lock (as
``threading.Event.set`` does) deadlocks when the signal lands while the main thread holds
that lock (inside ``Event.wait``), and the recorder then outlives the run. Once the bag is
closed the recorder leaves the graph (:func:`leave_graph`) within ``LEAVE_LIMIT_S``.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor

from hexapod_vibration.ros.executors import LoopSpinner

DRAIN_IDLE_S = 0.15
"""Time (s, wall) without a new message that ends the drain at shutdown."""
DRAIN_SPIN_S = 0.05
DRAIN_MAX_S = 10.0
"""Upper bound (s) of the drain at shutdown, reached only if publishers keep publishing
(a recorder behind a fast lockstep loop may have a few seconds of messages queued)."""
LEAVE_LIMIT_S = 2.0
"""Longest time (s, wall) the recorder spends leaving the graph once its bag is closed."""
BATCH_PERIOD_S = 0.01
"""Shortest time (s, wall) between two wake-ups of the recording loop. A wake-up costs the
thread a context switch and a pass over every subscription, tens of us, while writing a
message costs a few: waking for every message of the 1 kHz loop (six or more per sample)
was two thirds of the recorder's CPU. Taking what 10 ms brought at once keeps that cost per
10 ms; the subscriptions' queues (RECORDER_QOS) hold seconds, so nothing waits in vain."""


def drain(spinner: LoopSpinner, recorder: Any) -> None:
    """Write the messages still arriving: until DRAIN_IDLE_S without one, at most DRAIN_MAX_S."""
    now = time.monotonic()
    deadline, last_new = now + DRAIN_MAX_S, now
    while now - last_new < DRAIN_IDLE_S and now < deadline:
        before = recorder.total
        spinner.spin_once(DRAIN_SPIN_S)
        now = time.monotonic()
        if recorder.total != before:
            last_new = now


class StopFlag:
    """Set by the first SIGINT or SIGTERM; no lock (see the module docstring)."""

    def __init__(self) -> None:
        """Not set: no signal yet."""
        self.signum: int | None = None

    def is_set(self) -> bool:
        """True once a stop signal came."""
        return self.signum is not None

    def handler(self, signum: int, frame: object) -> None:
        """The signal handler: remember the first signal (its exit code is 128 + it)."""
        if self.signum is None:
            self.signum = signum


def install_stop_flag() -> StopFlag:
    """A flag set by SIGINT or SIGTERM (instead of rclpy's immediate shutdown)."""
    stop = StopFlag()
    signal.signal(signal.SIGINT, stop.handler)
    signal.signal(signal.SIGTERM, stop.handler)
    return stop


def record(recorder: Any, stop: StopFlag) -> None:
    """Record until ``stop``, then write what is queued and close the bag.

    The caller then leaves the graph (:func:`leave_graph`) and exits.
    """
    executor = SingleThreadedExecutor()
    executor.add_node(recorder)
    # The recorded topics are waited on in one persistent wait set and taken directly
    # (ros/executors.py); the executor serves the rest (timers, parameter services).
    spinner = LoopSpinner(executor, recorder.recorded_subscriptions, fast=True)
    try:
        while not stop.is_set():
            woke = time.monotonic()
            spinner.spin_once(0.1)
            rest_s = BATCH_PERIOD_S - (time.monotonic() - woke)
            if rest_s > 0.0 and not stop.is_set():
                time.sleep(rest_s)       # after a signal, at most BATCH_PERIOD_S more
        drain(spinner, recorder)
    finally:
        recorder.close_bag()


def leave_graph(recorder: Any, exit_now: Callable[[], None]) -> None:
    """Destroy the node and shut rclpy down, so the peers unmatch its readers at once.

    Deleting the DDS participant announces the readers' end. A process that exits without
    it stays matched in every peer until its lease runs out (about 20 s here): a driver or
    controller stopped with it (Ctrl-C of a launch, a test's teardown) then waited its whole
    exit flush (``ros.matching.FLUSH_S``, twice) for the acknowledgements of readers that
    were gone. The bag is closed before this, so nothing is lost if it stalls: once, the
    teardown hung for more than 90 s (a fresh-clone CI run), so ``exit_now`` ends the
    process from a timer after ``LEAVE_LIMIT_S`` whatever the teardown is doing.
    """
    timer = threading.Timer(LEAVE_LIMIT_S, exit_now)
    timer.daemon = True
    timer.start()
    recorder.destroy_node()
    rclpy.try_shutdown()
