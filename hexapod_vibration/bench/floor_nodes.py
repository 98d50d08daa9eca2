"""The loop's message path alone: the graph's processes with nothing computed in them.

``python -m hexapod_vibration.bench.floor_nodes ROLE --mode M --samples N --warmup W
[--priority P] [--recorder] --result FILE``, one process per role (``driver``, ``notch``,
``pointing``, ``recorder``; or ``composed``: driver and both controllers as three nodes of
one process and one wait set, as ``pph_graph``), on the same topics, QoS, persistent wait set
(``ros/executors.LoopSpinner``), serialized take and publish and CDR codec as the real
nodes (``make bench``'s message-path floor, :mod:`hexapod_vibration.bench.message_floor`):

- ``driver``: each sample publishes what the Table 1 driver publishes every sample
  (``/clock``, ``/pph/accel``, ``/pph/eddy``, ``/pph/actuator_force``,
  ``/pph/disturbance_frequencies``), the same values every time (no plant), and takes the
  two command streams; lockstep: advances once both answered (sample 0 offered again every
  50 ms until they did: the handshake); realtime: 1 kHz on the wall clock from the
  handshake, a command counted late if it is not in when the driver steps its sample + d
  (``command_delay_samples`` d, as the real driver). With ``--recorder`` it first holds
  until the recorder matched every publisher, as the real driver in an experiment.
- ``notch`` / ``pointing``: take ``/pph/accel`` / ``/pph/eddy`` (the newest d + 1 queued),
  decode them, answer each with a zero command of the same index.
- ``recorder``: takes every message of the seven topics every 10 ms and keeps none; at the
  stop it takes what is still queued (``recording_loop.drain``), as the real recorder.

Each process measures its own CPU (user + system, all threads: ``time.process_time``)
from sample ``W`` to the last sample it saw and writes ``{"samples", "cpu_s", "wall_s"}``
(and the driver ``"late"`` and the latency percentiles ``"latency_ms_p50"``, ``"_p99"``,
counted and timed by the real driver's ``CommandArbiter``: a sample's publication to the
arrival of its notch command) to FILE at SIGINT or SIGTERM or, for the driver, after N
samples.
Not computed anywhere: the plant, the control laws, the supervisor, diagnostics, forecasts,
the held-command reports, the bag (the every-10th-sample weights and forecasts of the real
controllers are not published either).
"""

from __future__ import annotations

import argparse
import gc
import json
import time
from functools import partial
from pathlib import Path

import numpy as np

from hexapod_vibration import cli
from hexapod_vibration.cdr import clock_cdr, decode_strut_cdr, encode_vector_cdr
from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    SAMPLE_RATE_HZ,
    STRUT_COUNT,
)
from hexapod_vibration.core.loop.command_arbiter import CommandArbiter
from hexapod_vibration.nodes.driver_loop import OFFER_AGAIN_S
from hexapod_vibration.parameter_specs import PPH_DRIVER
from hexapod_vibration.ros.messages import StrutArrayPublisher, create_loop_subscription
from hexapod_vibration.ros.recording_loop import BATCH_PERIOD_S, drain, install_stop_flag

ROLES = ("driver", "notch", "pointing", "recorder")
COMPOSED = "composed"
"""The role of the driver and both controllers composed in one process (``pph_graph``)."""
SAMPLE_TOPICS = ("/pph/accel", "/pph/eddy", "/pph/actuator_force")
COMMAND_TOPICS = {"notch": "/pph/notch_command", "pointing": "/pph/pointing_command"}
OBSERVED = {"notch": "/pph/accel", "pointing": "/pph/eddy"}
RUN = 1
"""The run id of every floor message (one run)."""
TIMEOUT_SAMPLES = PPH_DRIVER["command_timeout_samples"].default
"""The driver's ``command_timeout_samples`` default: how long a silent stream is waited for."""
FADE_SAMPLES = PPH_DRIVER["command_fade_samples"].default
"""The driver's ``command_fade_samples`` default: its watchdog's ramp to zero force."""


class CpuWindow:
    """CPU seconds of this process between loop sample ``warmup`` and the last one seen."""

    def __init__(self, warmup: int) -> None:
        """Open the window at sample ``warmup``."""
        self.warmup = warmup
        self.first_cpu_s = self.first_wall_s = None
        self.last_cpu_s = self.last_wall_s = 0.0
        self.last_sample = -1

    def saw(self, sample: int) -> None:
        """Note that the loop reached ``sample``."""
        if sample < self.warmup or sample <= self.last_sample:
            return
        cpu, wall = time.process_time(), time.perf_counter()
        if self.first_cpu_s is None:
            self.first_cpu_s, self.first_wall_s, self.first_sample = cpu, wall, sample
        self.last_cpu_s, self.last_wall_s, self.last_sample = cpu, wall, sample

    def result(self) -> dict[str, float]:
        """``samples`` in the window, its ``cpu_s`` and ``wall_s`` (zeros if never opened)."""
        if self.first_cpu_s is None:
            return {"samples": 0, "cpu_s": 0.0, "wall_s": 0.0}
        return {"samples": self.last_sample - self.first_sample,
                "cpu_s": self.last_cpu_s - self.first_cpu_s,
                "wall_s": self.last_wall_s - self.first_wall_s}


class FloorDriver:
    """Publishes the sample's five messages; pairs the command streams with samples.

    The pairing, the late commands and the latency are the real driver's
    :class:`~hexapod_vibration.core.loop.command_arbiter.CommandArbiter`'s.
    """

    def __init__(self, node, mode: str, delay: int) -> None:
        """Publishers and command subscriptions on ``node``."""
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64MultiArray

        from hexapod_vibration.ros.qos import CLOCK_QOS, COMMAND_QOS, LOOP_PUBLISHER_QOS
        from hexapod_vibration.ros.rclpy_internals import serialized_publish

        self.lockstep = mode == "lockstep"
        self.arbiter = CommandArbiter(tuple(COMMAND_TOPICS), tuple(COMMAND_TOPICS), RUN,
                                      limit_n=np.inf, latency_stream="notch",
                                      delay_samples=delay)
        publishers = {topic: node.create_publisher(Float64MultiArray, topic, LOOP_PUBLISHER_QOS)
                      for topic in (*SAMPLE_TOPICS, DISTURBANCE_FREQUENCIES_TOPIC)}
        publishers["/clock"] = node.create_publisher(Clock, "/clock", CLOCK_QOS)
        self._publishers = publishers
        self._arrays = [StrutArrayPublisher(publishers[topic]) for topic in SAMPLE_TOPICS]
        self._frequencies = serialized_publish(publishers[DISTURBANCE_FREQUENCIES_TOPIC])
        self._clock = serialized_publish(publishers["/clock"])
        self.subscriptions = [create_loop_subscription(
            node, topic, lambda raw, n=name: self._on_command(n, raw), COMMAND_QOS)
            for name, topic in COMMAND_TOPICS.items()]
        self._values = np.zeros(STRUT_COUNT)

    @property
    def sample(self) -> int:
        """The current sample."""
        return self.arbiter.sample

    def recorder_unmatched(self) -> bool:
        """True while a publisher lacks the recorder's reader (and a controller's, if read).

        As the real driver, which holds sample 0 until the recorder matched every publisher:
        the recorder's window then sees the samples from the first one.
        """
        return any(publisher.get_subscription_count() < 1 + (topic in OBSERVED.values())
                   for topic, publisher in self._publishers.items())

    def publish(self, again: bool = False) -> None:
        """This sample's /clock, sensors, force and tone frequencies (fixed values).

        ``again``: a lockstep re-offer of the current sample (the arbiter times the latency
        from the first publication, and counts the re-offers), as the real driver's
        ``publish_sample`` / ``offer_again``.
        """
        n = self.arbiter.sample
        if again:
            self.arbiter.offered_again()
        else:
            self.arbiter.published(time.perf_counter())
        self._clock(clock_cdr(n))
        for array in self._arrays:
            array.publish(self._values, n, RUN)
        self._frequencies(encode_vector_cdr([40.0, 80.0, 120.0], n, RUN))

    def _on_command(self, name: str, raw: bytes) -> None:
        command = decode_strut_cdr(raw)
        self.arbiter.offer(name, command.values, command.index, command.run,
                           time.perf_counter())

    def ready(self) -> bool:
        """Lockstep: both streams answered the sample due (the handshake: sample 0)."""
        return self.arbiter.ready(TIMEOUT_SAMPLES)

    def step(self) -> None:
        """Apply the due commands (realtime: a missing one counted late) and advance."""
        self.arbiter.close_sample(self.lockstep, TIMEOUT_SAMPLES, FADE_SAMPLES)
        self.arbiter.advance()

    def result(self) -> dict[str, float]:
        """Late commands and the latency percentiles (ms) since ``restart_stats``."""
        stats = self.arbiter.stats
        p50, p99 = stats.latencies_ms.percentiles((50, 99))
        return {"late": stats.late_commands, "latency_ms_p50": p50, "latency_ms_p99": p99}


class FloorController:
    """Takes the observed topic (newest d + 1 queued), answers every sample with zeros."""

    def __init__(self, node, role: str, window: CpuWindow) -> None:
        """Subscription and command publisher on ``node``."""
        from std_msgs.msg import Float64MultiArray

        from hexapod_vibration.ros.qos import LOOP_PUBLISHER_QOS, OBSERVED_LOOP_QOS

        self._window = window
        self._command = StrutArrayPublisher(node.create_publisher(
            Float64MultiArray, COMMAND_TOPICS[role], LOOP_PUBLISHER_QOS))
        self.subscriptions = [create_loop_subscription(node, OBSERVED[role], self._on_sample,
                                                       OBSERVED_LOOP_QOS)]
        self.latest_only = self.subscriptions
        self._zeros = np.zeros(STRUT_COUNT)

    def _on_sample(self, raw: bytes) -> None:
        sample = decode_strut_cdr(raw)
        self._command.publish(self._zeros, sample.index, sample.run)
        self._window.saw(sample.index)


class FloorRecorder:
    """Subscribes to the seven topics with the recorder's QoS; takes and drops everything."""

    def __init__(self, node, window: CpuWindow) -> None:
        """The subscriptions on ``node``."""
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64MultiArray

        from hexapod_vibration.cdr import sample_index_of_cdr
        from hexapod_vibration.ros.qos import RECORDER_CLOCK_QOS, RECORDER_QOS

        self.total = 0
        """Messages taken so far (what ``recording_loop.drain`` watches)."""
        index_of = sample_index_of_cdr

        def on_accel(raw: bytes) -> None:
            self.total += 1
            window.saw(index_of(raw) or 0)

        def on_other(raw: bytes) -> None:
            self.total += 1

        topics = [*SAMPLE_TOPICS, DISTURBANCE_FREQUENCIES_TOPIC, *COMMAND_TOPICS.values()]
        self.subscriptions = [node.create_subscription(
            Float64MultiArray, topic, on_accel if topic == "/pph/accel" else on_other,
            RECORDER_QOS, raw=True) for topic in topics]
        self.subscriptions.append(node.create_subscription(Clock, "/clock", on_other,
                                                           RECORDER_CLOCK_QOS, raw=True))


def _run_driver(spinner, driver: FloorDriver, args: argparse.Namespace,
                stop) -> dict[str, float]:
    """Handshake on sample 0, then ``args.samples`` samples; the window's result."""
    window = CpuWindow(args.warmup)
    period = 1.0 / SAMPLE_RATE_HZ
    while args.recorder and not stop.is_set() and driver.recorder_unmatched():
        spinner.spin_once(0.01)
    driver.arbiter.refresh_connections(dict.fromkeys(COMMAND_TOPICS, 1), TIMEOUT_SAMPLES)
    again = False
    while not stop.is_set() and driver.arbiter.unanswered():      # the handshake
        driver.publish(again)
        again = True
        deadline = time.perf_counter() + OFFER_AGAIN_S
        while driver.arbiter.unanswered() and time.perf_counter() < deadline:
            spinner.spin_once(0.005)
    start = time.perf_counter()
    answered = partial(driver.arbiter.answered, TIMEOUT_SAMPLES)
    while not stop.is_set() and driver.sample < args.samples:
        if driver.sample:
            driver.publish()
        if args.mode == "lockstep":
            offer_at = time.perf_counter() + OFFER_AGAIN_S
            while not driver.ready() and not stop.is_set():
                spinner.spin_once(max(offer_at - time.perf_counter(), 0.0), idle=False)
                if time.perf_counter() >= offer_at:
                    driver.publish(again=True)
                    offer_at = time.perf_counter() + OFFER_AGAIN_S
        else:
            deadline = start + (driver.sample + 1) * period
            spinner.spin_once(0.0, idle=answered)             # as the driver's loop
            while (remaining := deadline - time.perf_counter()) > 0.0:
                spinner.spin_once(remaining, idle=answered)
        window.saw(driver.sample)
        if driver.sample == args.warmup:
            driver.arbiter.restart_stats(time.perf_counter())
        driver.step()
    return {**window.result(), **driver.result()}


def _build_roles(args: argparse.Namespace, window: CpuWindow, create_node, executor) -> list:
    """The role objects of this process, each on its own node added to ``executor``.

    ``composed``: both controllers, then the driver (the order of ``run_node``'s
    subscriptions for ``pph_graph``: the controllers' callbacks run before the driver's).
    """
    def node(name: str):
        made = create_node(f"floor_{name}")
        executor.add_node(made)
        return made

    if args.role == COMPOSED:
        return [FloorController(node("notch"), "notch", window),
                FloorController(node("pointing"), "pointing", window),
                FloorDriver(node("driver"), args.mode, args.command_delay)]
    if args.role == "driver":
        return [FloorDriver(node("driver"), args.mode, args.command_delay)]
    if args.role == "recorder":
        return [FloorRecorder(node("recorder"), window)]
    return [FloorController(node(args.role), args.role, window)]


def run(args: argparse.Namespace) -> int:
    """Run one role until done (driver) or stopped (SIGINT/SIGTERM); write the result."""
    stop = install_stop_flag()
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from hexapod_vibration.ros.executors import LoopSpinner
    from hexapod_vibration.ros.fastdds_profile import use_package_profile
    from hexapod_vibration.ros.realtime import apply_scheduling

    use_package_profile()          # as run_node: the same DDS settings as the nodes
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    if args.priority and args.role != "recorder":      # as realtime_priority: loop nodes
        apply_scheduling(args.priority, [])
    executor = SingleThreadedExecutor()
    window = CpuWindow(args.warmup)
    roles = _build_roles(args, window, rclpy.create_node, executor)
    gc.freeze()        # as run_node: start-up objects never scanned again
    spinner = LoopSpinner(executor, [sub for role in roles for sub in role.subscriptions],
                          fast=True,
                          latest_only=[sub for role in roles
                                       for sub in getattr(role, "latest_only", ())],
                          answered=args.command_delay + 1)
    if args.role in ("driver", COMPOSED):
        result = _run_driver(spinner, roles[-1], args, stop)
    else:
        while not stop.is_set():
            woke = time.monotonic()
            spinner.spin_once(0.1)
            if args.role == "recorder":        # the recorder's batching (recording_loop)
                rest_s = BATCH_PERIOD_S - (time.monotonic() - woke)
                if rest_s > 0.0 and not stop.is_set():
                    time.sleep(rest_s)
        if args.role == "recorder":      # what is queued at the stop, as the real recorder
            drain(spinner, roles[0])
        result = window.result()
    Path(args.result).write_text(json.dumps(result))
    return cli.EXIT_OK


def main(argv: list[str] | None = None) -> None:
    """Entry point (``python -m hexapod_vibration.bench.floor_nodes``); see the docstring."""
    parser = argparse.ArgumentParser(
        prog="floor_nodes", description="One process of the loop's message path, nothing "
        "computed (make bench's message-path floor).")
    parser.add_argument("role", choices=(*ROLES, COMPOSED))
    parser.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    parser.add_argument("--samples", type=cli.number(1, 10**8, integer=True), default=20000,
                        help="samples the driver runs (default 20000)")
    parser.add_argument("--warmup", type=cli.number(0, 10**8, integer=True), default=2000,
                        help="samples before the measured window (default 2000)")
    parser.add_argument("--command-delay", type=cli.number(0, 10, integer=True), default=2,
                        help="command_delay_samples d (default 2)")
    parser.add_argument("--priority", type=cli.number(0, 98, integer=True), default=0,
                        help="SCHED_FIFO priority of the loop roles (0: normal scheduling)")
    parser.add_argument("--recorder", action="store_true",
                        help="driver: hold sample 0 until the recorder matched every publisher")
    parser.add_argument("--result", required=True, help="JSON file written at the end")
    cli.exit_now(run(parser.parse_args(argv)))


if __name__ == "__main__":
    main()
