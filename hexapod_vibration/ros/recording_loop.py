"""The recorder's loop: everything queued taken at most every ``BATCH_PERIOD_S``, written.

At SIGINT/SIGTERM what is still queued is written before the bag is closed.
"""

from __future__ import annotations

import signal
import threading
import time
from typing import Any

from rclpy.executors import SingleThreadedExecutor

from hexapod_vibration.ros.executors import LoopSpinner

DRAIN_IDLE_SPINS = 3
"""Consecutive idle spins (each up to DRAIN_SPIN_S) that end the drain at shutdown."""
DRAIN_SPIN_S = 0.05
DRAIN_MAX_S = 10.0
"""Upper bound (s) of the drain at shutdown, reached only if publishers keep publishing
(a recorder behind a fast lockstep loop may have a few seconds of messages queued)."""
BATCH_PERIOD_S = 0.01
"""Shortest time (s, wall) between two wake-ups of the recording loop. A wake-up costs the
thread a context switch and a pass over every subscription, tens of us, while writing a
message costs a few: waking for every message of the 1 kHz loop (six or more per sample)
was two thirds of the recorder's CPU. Taking what 10 ms brought at once keeps that cost per
10 ms; the subscriptions' queues (RECORDER_QOS) hold seconds, so nothing waits in vain."""


def _drain(spinner: LoopSpinner, recorder: Any) -> None:
    """Write the messages already queued: spin until idle, at most DRAIN_MAX_S."""
    deadline = time.monotonic() + DRAIN_MAX_S
    idle = 0
    while idle < DRAIN_IDLE_SPINS and time.monotonic() < deadline:
        before = recorder.total
        spinner.spin_once(DRAIN_SPIN_S)
        idle = idle + 1 if recorder.total == before else 0


def install_stop_event() -> threading.Event:
    """An event set by SIGINT or SIGTERM (instead of rclpy's immediate shutdown)."""
    stop = threading.Event()

    def handler(signum: int, frame: object) -> None:
        stop.signum = getattr(stop, "signum", signum)   # the first one: the exit code
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def record(recorder: Any, stop: threading.Event) -> None:
    """Record until ``stop``, then write what is queued and close the bag."""
    executor = SingleThreadedExecutor()
    executor.add_node(recorder)
    # The recorded topics are waited on in one persistent wait set and taken directly
    # (ros/executors.py); the executor serves the rest (timers, parameter services).
    spinner = LoopSpinner(executor, recorder.recorded_subscriptions, fast=True)
    try:
        while not stop.is_set():
            woke = time.monotonic()
            spinner.spin_once(0.1)
            stop.wait(BATCH_PERIOD_S - (time.monotonic() - woke))
        _drain(spinner, recorder)
    finally:
        recorder.close_bag()
        executor.remove_node(recorder)
        recorder.destroy_node()


