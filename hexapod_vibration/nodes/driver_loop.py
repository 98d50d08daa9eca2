"""The driver's clock: lockstep (advance when the commands arrived) and realtime (1 kHz wall).

These functions pace a :class:`~hexapod_vibration.nodes.pph_driver.PPHDriver`: they publish
each sample, serve its spinner until the sample's commands are in (lockstep) or its wall-clock
deadline passed (realtime), then apply them and step the plant. The node moves messages; the
pairing of commands with samples is :class:`~hexapod_vibration.core.loop.command_arbiter.
CommandArbiter`'s.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import rclpy

from hexapod_vibration.ros.executors import LoopSpinner
from hexapod_vibration.ros.matching import FLUSH_S

OFFER_AGAIN_S = 0.05
"""Lockstep: wall time (s) after which a sample whose commands are missing is published
again (controllers answer a repeated sample with the same command): a command lost in
transit (e.g. pushed out of a full queue by a flood) costs 50 ms, not the timeout."""
HANDSHAKE_LOG_S = 5.0
"""Period (s, wall) of the handshake's "waiting for ..." log."""
REALTIME_HANDSHAKE_S = 5.0
"""Realtime: longest wait (s, wall) for the expected controllers to answer sample 0 before
the clock starts (discovery of a restarted driver takes up to about a second here; a
controller that is not there is not waited for longer)."""
REFRESH_EVERY_SAMPLES = 200
"""Samples between two looks at the graph for the command streams' publishers."""


class PPHDriver(Protocol):
    """What the pacing needs of the driver node (``nodes.pph_driver.PPHDriver``)."""

    mode: str
    fs: float
    outputs: Any
    sample: int
    lockstep_timeout_s: float

    def held(self) -> bool: ...                                 # noqa: D102
    def paused(self, held: bool) -> None: ...                   # noqa: D102
    def commands_ready(self) -> bool: ...                       # noqa: D102
    def answered(self) -> bool: ...                             # noqa: D102
    def unanswered(self) -> list[str]: ...                      # noqa: D102
    def publish_sample(self) -> None: ...                       # noqa: D102
    def offer_again(self) -> None: ...                          # noqa: D102
    def timed_out(self) -> None: ...                            # noqa: D102
    def restart_stats(self) -> None: ...                        # noqa: D102
    def refresh_connections(self) -> None: ...                  # noqa: D102
    def apply_and_step(self) -> None: ...                       # noqa: D102
    def publish_diagnostics(self, held: bool = False) -> None: ...  # noqa: D102
    def get_logger(self) -> Any: ...                            # noqa: D102


def wait_while_held(node: PPHDriver, spinner: LoopSpinner) -> None:
    """The breakpoint: serve callbacks (parameters) until ``hold_at_time_s`` moves on.

    At any sample, in both clock modes (realtime: the clock stops; it resumes from the
    breakpoint, :func:`run_realtime`).

    On entering the hold the driver publishes the force it applied last (a realtime
    driver defers it to the next sample) and reports ``held: true`` with its sample on
    /diagnostics, so a supervisor (the experiment runner) knows the loop stopped exactly
    before publishing that sample, with everything before it published.
    """
    if not node.held():
        return
    node.outputs.flush_force()
    node.paused(True)
    announced = 0.0
    while node.held() and rclpy.ok():
        if time.perf_counter() - announced > 0.5:      # late subscribers hear it too
            node.publish_diagnostics(held=True)
            announced = time.perf_counter()
        spinner.spin_once(timeout_sec=0.01)
    node.paused(False)


def wait_for_controllers(node: PPHDriver, spinner: LoopSpinner,
                         limit_s: float = float("inf")) -> None:
    """Offer sample 0 again and again until every expected controller answered it.

    Discovery does not tell when a subscription can receive: offering the first sample
    again (controllers answer a repeated sample with the same command) is a handshake that
    loses nothing. A controller following an older run adopts this one within a few offers.
    Lockstep waits as long as it takes; realtime at most ``limit_s`` (s, wall).
    """
    node.publish_sample()
    start = last_log = time.perf_counter()
    while rclpy.ok() and time.perf_counter() - start < limit_s:
        deadline = time.perf_counter() + OFFER_AGAIN_S
        while (remaining := deadline - time.perf_counter()) > 0.0:
            spinner.spin_once(timeout_sec=remaining)
        missing = node.unanswered()
        if not missing:
            break
        if time.perf_counter() - last_log > HANDSHAKE_LOG_S:
            node.get_logger().info(f"waiting for {', '.join(missing)} to answer sample 0")
            last_log = time.perf_counter()
        node.offer_again()
    node.restart_stats()
    node.refresh_connections()


def wait_for_commands(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Lockstep: serve callbacks until every waited controller answered the current sample.

    The sample is offered again every ``OFFER_AGAIN_S`` while a command is missing; after
    ``lockstep_timeout_s`` and as many offers as fit in it, the wait gives up (counted) and
    the loop advances without it. Counting offers too keeps a driver that got no CPU for a
    while (a loaded machine, a flood) from timing out before its controllers had the chances
    the timeout promises.
    """
    now = time.perf_counter()
    timeout_s = node.lockstep_timeout_s
    deadline, offer_at = now + timeout_s, now + OFFER_AGAIN_S
    offers_due, offers = int(timeout_s / OFFER_AGAIN_S), 0
    spun = False
    while not node.commands_ready():
        now = time.perf_counter()
        if now >= deadline and offers >= offers_due:
            node.timed_out()
            break
        if now >= offer_at:
            node.offer_again()
            offers += 1
            offer_at = now + OFFER_AGAIN_S
        until = offer_at if now >= deadline else min(deadline, offer_at)
        spinner.spin_once(timeout_sec=max(until - now, 0.0), idle=False)
        spun = True
    if not spun:    # nothing to wait for: still serve parameters and other streams
        spinner.spin_once(timeout_sec=0.0)


def run_lockstep(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Advance as soon as every connected controller answered the current sample.

    Only the controllers of ``lockstep_controllers`` are waited for, each up to
    ``lockstep_timeout_s`` per sample, and not once the watchdog dropped its stream.
    """
    wait_while_held(node, spinner)
    wait_for_controllers(node, spinner)
    if rclpy.ok():
        node.apply_and_step()      # sample 0 is out and answered already (handshake)
    while rclpy.ok():
        wait_while_held(node, spinner)
        node.publish_sample()
        wait_for_commands(node, spinner)
        if node.sample % REFRESH_EVERY_SAMPLES == 0:
            node.refresh_connections()
        node.apply_and_step()


def run_realtime(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Pace the loop at the sample rate on the wall clock, as hardware would.

    The clock starts once the expected controllers answered sample 0 (at most
    ``REALTIME_HANDSHAKE_S``), so a restarted driver is answered from its first samples.
    A breakpoint (``hold_at_time_s``) stops the clock before its sample; released, the
    clock resumes there (the sample is due one period after the release): a hold is a
    pause of the loop, not samples missed. The experiment runner ends a realtime run at a
    breakpoint, so the recorder can catch up with every sample before the driver exits.
    """
    period, answered = 1.0 / node.fs, node.answered
    wait_while_held(node, spinner)             # the start breakpoint (hold_at_time_s 0)
    wait_for_controllers(node, spinner, REALTIME_HANDSHAKE_S)
    start = time.perf_counter() - period      # sample 0's period was the handshake's
    if rclpy.ok():
        node.apply_and_step()      # sample 0 is out (and answered, unless the wait ran out)
    while rclpy.ok():
        if node.held():
            wait_while_held(node, spinner)
            start = time.perf_counter() - node.sample * period
        node.publish_sample()
        deadline = start + (node.sample + 1) * period
        # After an overrun: what is here is not late. Idle (deferred work, the services)
        # once the sample's commands are in.
        spinner.spin_once(timeout_sec=0.0, idle=answered)
        while (remaining := deadline - time.perf_counter()) > 0.0:
            spinner.spin_once(timeout_sec=remaining, idle=answered)
        if node.sample % REFRESH_EVERY_SAMPLES == 0:
            node.refresh_connections()
        node.apply_and_step()


def run_driver(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Run the loop of the driver's ``clock_mode`` until shutdown, then report once more.

    At exit every published sample is delivered first (at most ``FLUSH_S``): a recorder
    behind a realtime loop had lost the last 0.6 s of a run when the driver exited. A topic
    still unacknowledged then is logged (its readers may lack the run's last samples).
    """
    node.restart_stats()
    try:
        (run_lockstep if node.mode == "lockstep" else run_realtime)(node, spinner)
    finally:
        if rclpy.ok():
            node.outputs.flush_force()
            unacknowledged = node.outputs.readers.wait_for_acks(FLUSH_S)
            if unacknowledged:
                node.get_logger().warning(
                    f"exit: {', '.join(unacknowledged)} not acknowledged by every reader "
                    f"within {FLUSH_S:.0f} s: a reader may lack the last samples")
            node.publish_diagnostics()
