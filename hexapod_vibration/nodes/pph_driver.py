"""``pph_driver``: the simulated Precision Pointing Hexapod as a ROS 2 node.

Every sample n (1 kHz) it publishes ``/clock`` (n ms of sim time), ``/pph/accel`` and
``/pph/eddy`` (in-band sample index n), waits for the commands of sample n (lockstep) or
until the sample's wall-clock deadline (realtime), sums ``/pph/notch_command`` and
``/pph/pointing_command``, saturates them, publishes ``/pph/actuator_force`` (what is
applied over [n, n+1)) and advances the plant by one sample. A command stream whose last
valid command is older than ``command_timeout_samples`` is dropped to zero force (watchdog).
Health and loop statistics go to ``/diagnostics`` once per simulated second.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import PPHPlant, actuator_test_sine, saturate_commands
from hexapod_vibration.core.model.shaker import Shaker, tones_from_arrays
from hexapod_vibration.parameter_specs import (
    LOCKSTEP_STREAMS,
    PPH_DRIVER,
    shaker_tone_arrays,
    shaker_unpaired,
)
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.diagnostics import clock_cdr, diagnostic_array
from hexapod_vibration.ros.executors import LoopSpinner, run_node
from hexapod_vibration.ros.messages import StrutArrayPublisher, receive_strut_array
from hexapod_vibration.ros.parameters import NodeParameters
from hexapod_vibration.ros.qos import CLOCK_QOS, DIAGNOSTICS_QOS, LOOP_PUBLISHER_QOS, LOOP_QOS

STREAMS = LOCKSTEP_STREAMS
NO_FORCE_N = np.zeros(6)    # read-only: what a stale stream contributes
NO_FORCE_N.flags.writeable = False
PUBLISH_HISTORY = 1024      # samples whose publication time is kept for the latency
STATS_WINDOW = 60000
"""Latencies and periods kept for the percentiles on /diagnostics (the last minute at 1 kHz)."""
SHAKER_PARAMS = ("shaker_frequencies_hz", "shaker_amplitudes_n", "shaker_phases_rad",
                 "shaker_drift_hz", "shaker_drift_period_s", "shaker_noise_rms_n")


@dataclass
class CommandStream:
    """Latest valid command of one controller and its bookkeeping."""

    topic: str
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(6))
    sample: int = -1
    received_wall_s: float = 0.0
    invalid: int = 0
    late: int = 0
    stale: bool = True
    stale_events: int = 0
    connected: bool = False


@dataclass
class LoopStats:
    """Measured loop statistics (wall clock), reported on /diagnostics."""

    samples: int = 0
    timeouts: int = 0
    missed: int = 0
    late_commands: int = 0
    start_wall_s: float = 0.0
    latencies_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_WINDOW))
    periods_ms: deque = field(default_factory=lambda: deque(maxlen=STATS_WINDOW))
    last_publish_wall_s: float = 0.0


class PPHDriver(Node):
    """Simulated hexapod: plant stepping, sensor publishing, command watchdog."""

    def __init__(self) -> None:
        """Declare parameters, build the plant, create publishers and subscriptions."""
        super().__init__("pph_driver")
        self._declare_parameters()
        self.mode = self.params["clock_mode"]
        model = load_model_config(self.params["model_file"] or config_path("pph_model.yaml"))
        self.model = model if self.params["nonlinear"] else model.linear()
        seed = self.params["seed"]
        self.plant = PPHPlant(self.model, shaker=self._make_shaker(seed), seed=seed)
        self.fs = self.model.simulation.sample_rate_hz
        self.sample = 0
        self._publish_wall_s = np.zeros(PUBLISH_HISTORY)
        self.stats = LoopStats()
        self.streams = {s: CommandStream(f"/pph/{s}_command") for s in STREAMS}
        pub_qos = LOOP_PUBLISHER_QOS
        self._pub_accel = StrutArrayPublisher(self.create_publisher(
            Float64MultiArray, "/pph/accel", pub_qos))
        self._pub_eddy = StrutArrayPublisher(self.create_publisher(
            Float64MultiArray, "/pph/eddy", pub_qos))
        self._pub_force = StrutArrayPublisher(self.create_publisher(
            Float64MultiArray, "/pph/actuator_force", pub_qos))
        self._pub_clock = self.create_publisher(Clock, "/clock", CLOCK_QOS)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.loop_subscriptions = [
            self.create_subscription(Float64MultiArray, stream.topic,
                                     lambda msg, n=name: self._on_command(n, msg), LOOP_QOS)
            for name, stream in self.streams.items()]
        self._serve_parameters()
        self._sample_pending = self.plant.step(np.zeros(6))
        self.get_logger().info(
            f"PPH driver up: {self.mode}, {'nonlinear' if self.model is model else 'linear'}"
            f" plant, {self.fs:.0f} Hz, watchdog {self._timeout_samples} samples")

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        """Declare and check every parameter (``parameter_specs.PPH_DRIVER``)."""
        self.params = NodeParameters(self, PPH_DRIVER)
        self._apply_parameters(self.params.values(), startup=True)

    def _serve_parameters(self) -> None:
        """Run-time changes: validated in on-set, applied in post-set."""
        self.params.serve(apply=self._apply_parameters)

    def _make_shaker(self, seed: int) -> Shaker:
        values = self.params.values()
        return Shaker(self._shaker_tones(values), values["shaker_noise_rms_n"],
                      self.model.shaker.force_limit_n, seed=seed + 1)

    @staticmethod
    def _shaker_tones(values: dict) -> list:
        """The sounding tones (``parameter_specs.shaker_tone_arrays``) as ShakerTones."""
        return tones_from_arrays(*shaker_tone_arrays(values), values["shaker_drift_hz"],
                                 values["shaker_drift_period_s"])

    def _apply_parameters(self, changes: dict, startup: bool = False) -> None:
        """Apply validated values (post-set at run time; every value at start-up)."""
        if "command_timeout_samples" in changes:
            self._timeout_samples = int(changes["command_timeout_samples"])
        for name in ("test_sine_frequency_hz", "test_sine_amplitude_n", "hold_at_time_s",
                     "lockstep_timeout_s"):
            if name in changes:
                setattr(self, f"_{name}", float(changes[name]))
        if "lockstep_controllers" in changes:
            self._expected = list(changes["lockstep_controllers"])
        if not any(name in changes for name in SHAKER_PARAMS):
            return
        values = self.params.values()
        unpaired = shaker_unpaired(values)
        if unpaired:
            self.get_logger().warn(unpaired)
        if startup:
            return                      # the plant's shaker is built from the same values
        self.plant.shaker.set_tones(self._shaker_tones(values))
        self.plant.shaker.noise_rms_n = float(values["shaker_noise_rms_n"])

    # ------------------------------------------------------------------ commands
    def _on_command(self, name: str, msg: Float64MultiArray | bytes) -> None:
        stream = self.streams[name]
        parsed = receive_strut_array(msg, self.get_logger(), stream.topic)
        if parsed is None:
            stream.invalid += 1
            return
        values, index = parsed
        index = self.sample if index is None else index
        if index > self.sample or index < stream.sample:
            stream.invalid += 1       # from the future or out of order: never applied
            return
        stream.force_n = np.array(values)
        stream.sample = index
        stream.received_wall_s = time.perf_counter()
        published = self._publish_wall_s[index % PUBLISH_HISTORY]
        if name == "notch" and self.sample - index < PUBLISH_HISTORY and published > 0.0:
            # accel(index) publication to notch_command(index) reception, late ones included
            self.stats.latencies_ms.append((stream.received_wall_s - published) * 1e3)

    def _fresh(self, stream: CommandStream) -> bool:
        """The stream's last valid command is at most ``command_timeout_samples`` old."""
        return stream.sample >= 0 and self.sample - stream.sample <= self._timeout_samples

    def _refresh_connections(self) -> None:
        """A stream is connected if the graph shows a publisher or it commanded recently.

        The graph (count_publishers) can lag behind the data: a controller that answered
        the handshake may not be listed yet, and it must be waited for all the same.
        """
        for stream in self.streams.values():
            stream.connected = self._fresh(stream) or self.count_publishers(stream.topic) > 0

    def _waited_streams(self) -> list[CommandStream]:
        """Expected controllers that are connected and not dropped by the watchdog.

        A controller that missed more than ``command_timeout_samples`` samples (e.g. its
        process died, which discovery may notice only many seconds later) is not waited for
        any more, so the loop runs on without it; it is waited for again once it answers.
        """
        return [s for s in (self.streams[n] for n in self._expected)
                if s.connected and self._fresh(s)]

    def _commands_ready(self) -> bool:
        return all(s.sample == self.sample for s in self._waited_streams())

    def _count_missed(self) -> None:
        """Lockstep: count the sample if a connected expected controller did not answer it."""
        if any(self.streams[n].connected and self.streams[n].sample != self.sample
               for n in self._expected):
            self.stats.missed += 1

    def _active_force(self, name: str) -> np.ndarray:
        """The stream's force, or zero if its last valid command is too old (watchdog)."""
        stream = self.streams[name]
        stale = not self._fresh(stream)
        if stale and not stream.stale and stream.sample >= 0:
            stream.stale_events += 1
            self.get_logger().warn(f"{stream.topic}: no command for {self._timeout_samples} "
                                   f"samples, force set to zero")
        stream.stale = stale
        return NO_FORCE_N if stale else stream.force_n

    # ------------------------------------------------------------------ loop
    def publish_sample(self) -> None:
        """Publish /clock and the sensors of the current sample."""
        n, sensors = self.sample, self._sample_pending
        self._pub_clock.publish(clock_cdr(n, self.fs))
        self._pub_accel.publish(sensors.accel_m_s2, n)
        self._pub_eddy.publish(sensors.eddy_m, n)
        now = time.perf_counter()
        self._publish_wall_s[n % PUBLISH_HISTORY] = now
        if self.stats.last_publish_wall_s:
            self.stats.periods_ms.append((now - self.stats.last_publish_wall_s) * 1e3)
        self.stats.last_publish_wall_s = now

    def apply_and_step(self) -> None:
        """Sum, saturate, publish the applied force and advance the plant one sample."""
        notch = self._active_force("notch")
        if self._test_sine_amplitude_n > 0.0:
            notch = notch + actuator_test_sine(self.sample, self._test_sine_frequency_hz,
                                               self._test_sine_amplitude_n, self.fs)
        applied = saturate_commands(notch, self._active_force("pointing"), self.model.strut)
        self._pub_force.publish(applied, self.sample)
        self._sample_pending = self.plant.step(applied)
        self.sample += 1
        self.stats.samples += 1
        if self.sample % int(self.fs) == 0:
            self.publish_diagnostics()

    def held(self) -> bool:
        """True while the lockstep breakpoint ``hold_at_time_s`` stops the loop here."""
        hold = self._hold_at_time_s
        return self.mode == "lockstep" and hold >= 0.0 and self.sample >= round(hold * self.fs)

    def publish_diagnostics(self, held: bool = False) -> None:
        """Loop health and statistics on /diagnostics (``held``: at the breakpoint)."""
        st = self.stats
        wall = max(time.perf_counter() - st.start_wall_s, 1e-9)
        lat = np.array(st.latencies_ms) if st.latencies_ms else np.array([np.nan])
        per = np.array(st.periods_ms) if st.periods_ms else np.array([np.nan])
        # Stale: connected, or sent commands before (a controller that went away).
        stale = [n for n, s in self.streams.items()
                 if s.stale and (s.connected or s.sample >= 0)]
        values = {
            "mode": self.mode, "sample": self.sample, "samples": st.samples, "held": held,
            "rate_hz": st.samples / wall, "timeouts": st.timeouts,
            "late_commands": st.late_commands,
            "missed_samples": st.missed if self.mode == "lockstep" else st.late_commands,
            "latency_ms_p50": np.percentile(lat, 50), "latency_ms_p99": np.percentile(lat, 99),
            "latency_ms_max": np.max(lat), "period_ms_p50": np.percentile(per, 50),
            "period_ms_p99": np.percentile(per, 99), "period_ms_max": np.max(per),
            "fallback_samples": self.plant.fallback_samples,
            "accel_clipped_samples": self.plant.accelerometers.clipped_samples,
        }
        for name, s in self.streams.items():
            values.update({f"{name}_invalid": s.invalid, f"{name}_stale_events": s.stale_events,
                           f"{name}_late": s.late,
                           f"{name}_connected": s.connected})
        invalid = any(s.invalid for s in self.streams.values())
        warn = bool(stale or st.timeouts or st.missed or invalid)
        message = f"stale: {', '.join(stale)}" if stale else "ok"
        self._pub_diag.publish(diagnostic_array("pph_driver: loop", warn, message, values,
                                                self.sample))


def wait_while_held(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Lockstep breakpoint: serve callbacks (parameters) until ``hold_at_time_s`` moves on.

    On entering the hold the driver reports ``held: true`` with its sample on
    /diagnostics, so a supervisor (the experiment runner) knows the loop stopped exactly
    before publishing that sample.
    """
    if not node.held():
        return
    announced = 0.0
    while node.held() and rclpy.ok():
        if time.perf_counter() - announced > 0.5:      # late subscribers hear it too
            node.publish_diagnostics(held=True)
            announced = time.perf_counter()
        spinner.spin_once(timeout_sec=0.01)


def wait_for_controllers(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Offer sample 0 again and again until every expected controller answered it.

    Discovery does not tell when a subscription can receive: re-publishing the first
    sample (controllers ignore duplicates) is a handshake that loses nothing.
    """
    last_log = time.perf_counter()
    while rclpy.ok():
        node.publish_sample()
        deadline = time.perf_counter() + 0.05
        while time.perf_counter() < deadline:
            spinner.spin_once(timeout_sec=max(deadline - time.perf_counter(), 0.0))
        missing = [n for n in node._expected if node.streams[n].sample != 0]
        if not missing:
            break
        if time.perf_counter() - last_log > 5.0:
            node.get_logger().info(f"waiting for {', '.join(missing)} to answer sample 0")
            last_log = time.perf_counter()
    node.stats = LoopStats(start_wall_s=time.perf_counter())
    node._refresh_connections()


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
        deadline = time.perf_counter() + node._lockstep_timeout_s
        spun = False
        while not node._commands_ready():
            remaining = deadline - time.perf_counter()
            if remaining <= 0.0:
                node.stats.timeouts += 1
                node._refresh_connections()
                break
            spinner.spin_once(timeout_sec=remaining)
            spun = True
        if not spun:    # nothing to wait for: still serve parameters and other streams
            spinner.spin_once(timeout_sec=0.0)
        if node.sample % 200 == 0:
            node._refresh_connections()
        node._count_missed()
        node.apply_and_step()


def run_realtime(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Pace the loop at the sample rate on the wall clock, as hardware would."""
    period = 1.0 / node.fs
    start = time.perf_counter()
    node._refresh_connections()
    while rclpy.ok():
        node.publish_sample()
        deadline = start + (node.sample + 1) * period
        spinner.spin_once(timeout_sec=0.0)   # after an overrun: what is here is not late
        while (remaining := deadline - time.perf_counter()) > 0.0:
            spinner.spin_once(timeout_sec=remaining)
        late = [s for s in node.streams.values() if s.connected and s.sample < node.sample]
        for stream in late:
            stream.late += 1
        if late:
            node.stats.late_commands += 1
        if node.sample % 200 == 0:
            node._refresh_connections()
        node.apply_and_step()


def run_driver(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Run the loop of the driver's ``clock_mode`` until shutdown, then report once more."""
    node.stats.start_wall_s = time.perf_counter()
    try:
        (run_lockstep if node.mode == "lockstep" else run_realtime)(node, spinner)
    finally:
        if rclpy.ok():
            node.publish_diagnostics()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration pph_driver``."""
    run_node("pph_driver", PPHDriver, run_driver, args=args)


if __name__ == "__main__":
    main()
