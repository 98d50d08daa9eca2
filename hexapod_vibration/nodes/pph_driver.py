"""``pph_driver``: the simulated Precision Pointing Hexapod as a ROS 2 node.

Every sample n (1 kHz) it publishes ``/clock`` (n ms of sim time), ``/pph/accel`` and
``/pph/eddy`` (in-band sample index n and the run's identity), waits for the commands of
sample n (lockstep; the sensors are offered again every ``OFFER_AGAIN_S`` while one is
missing) or until the sample's wall-clock deadline (realtime), sums ``/pph/notch_command``
and ``/pph/pointing_command``, saturates them, publishes ``/pph/actuator_force`` (what is
applied over [n, n+1)) and advances the plant by one sample. Which command of each stream
applies (the first valid one per sample; zero force once a stream is older than
``command_timeout_samples``) is decided by the pure
:class:`~hexapod_vibration.core.loop.command_arbiter.CommandArbiter`; this node moves
messages and parameters. Health and loop statistics go to ``/diagnostics`` once per
simulated second.

A rotating machine (parameters ``rotor_*``, :class:`~hexapod_vibration.core.model.rotor.Rotor`)
may act at the shaker's point. With ``rotor_tachometer`` on, its speed for sample n (Hz, at
the time the sample's sensors are read) goes out on ``/pph/reference_frequency`` just before
the sample's sensors. The true frequency of every sounding tone (shaker tones with their
drift, then the rotor's orders) goes out on ``/pph/disturbance_frequencies`` every
``FREQUENCIES_EVERY_SAMPLES`` samples, for the analysis.
"""

from __future__ import annotations

import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    DRIVER_STATUS,
    FREQUENCIES_EVERY_SAMPLES,
    REFERENCE_FREQUENCY_TOPIC,
    new_run_id,
)
from hexapod_vibration.core.loop.command_arbiter import CommandArbiter
from hexapod_vibration.core.loop.signal_ranges import SignalRanges
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import PPHPlant, actuator_test_sine, saturate_commands
from hexapod_vibration.core.model.rotor import Rotor, rotor_or_none
from hexapod_vibration.core.model.shaker import Shaker, tones_from_arrays
from hexapod_vibration.parameter_specs import (
    LOCKSTEP_STREAMS,
    PPH_DRIVER,
    rotor_arrays,
    rotor_unpaired,
    shaker_tone_arrays,
    shaker_unpaired,
)
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.diagnostics import diagnostic_array
from hexapod_vibration.ros.executors import LoopSpinner, run_node
from hexapod_vibration.ros.matching import MatchedReaders
from hexapod_vibration.ros.messages import (
    StrutArrayPublisher,
    create_loop_subscription,
    make_vector_array,
    receive_strut_sample,
)
from hexapod_vibration.ros.parameters import NodeParameters
from hexapod_vibration.ros.qos import (
    CLOCK_QOS,
    COMMAND_QOS,
    DIAGNOSTICS_QOS,
    LOOP_PUBLISHER_QOS,
)
from hexapod_vibration.ros.rclpy_internals import clock_cdr, serialized_publish

STREAMS = LOCKSTEP_STREAMS
SHAKER_PARAMS = ("shaker_frequencies_hz", "shaker_amplitudes_n", "shaker_phases_rad",
                 "shaker_drift_hz", "shaker_drift_period_s", "shaker_noise_rms_n")
ROTOR_PARAMS = ("rotor_orders", "rotor_amplitudes_n", "rotor_reference_speed_hz",
                "rotor_profile_time_s", "rotor_profile_speed_hz")
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


class PPHDriver(Node):
    """Simulated hexapod: plant stepping, sensor publishing, commands through the arbiter."""

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
        self.run_id = new_run_id()
        self.arbiter = CommandArbiter(STREAMS, self._expected, self.run_id,
                                      SignalRanges.from_model(self.model).command_n,
                                      latency_stream="notch")
        self.topics = {name: f"/pph/{name}_command" for name in STREAMS}
        self.readers = MatchedReaders(lambda: self.publish_diagnostics(held=self.held()))
        arrays = {topic: self.readers.publisher(self, Float64MultiArray, topic, LOOP_PUBLISHER_QOS)
                  for topic in ("/pph/accel", "/pph/eddy", "/pph/actuator_force",
                                REFERENCE_FREQUENCY_TOPIC, DISTURBANCE_FREQUENCIES_TOPIC)}
        self._pub_accel = StrutArrayPublisher(arrays["/pph/accel"])
        self._pub_eddy = StrutArrayPublisher(arrays["/pph/eddy"])
        self._pub_force = StrutArrayPublisher(arrays["/pph/actuator_force"])
        self._pub_reference = arrays[REFERENCE_FREQUENCY_TOPIC]
        self._pub_frequencies = arrays[DISTURBANCE_FREQUENCIES_TOPIC]
        self._reference_msg: Float64MultiArray | None = None
        self._pub_clock = serialized_publish(self.readers.publisher(self, Clock, "/clock",
                                                                    CLOCK_QOS))
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.loop_subscriptions = [
            create_loop_subscription(self, topic, lambda msg, n=name: self._on_command(n, msg),
                                     COMMAND_QOS)
            for name, topic in self.topics.items()]
        self._serve_parameters()
        self._sample_pending = self.plant.step(np.zeros(6))
        self._offer: tuple[bytes, ...] = ()
        self.get_logger().info(
            f"PPH driver up: {self.mode}, {'nonlinear' if self.model is model else 'linear'}"
            f" plant, {self.fs:.0f} Hz, watchdog {self._timeout_samples} samples, "
            f"run {self.run_id}")

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
                      self.model.shaker.force_limit_n, seed=seed + 1,
                      rotor=self._make_rotor(values))

    @staticmethod
    def _make_rotor(values: dict) -> Rotor | None:
        """The rotor of the sounding ``rotor_*`` values (``parameter_specs.rotor_arrays``)."""
        orders, amplitudes, times, speeds = rotor_arrays(values)
        return rotor_or_none(orders, amplitudes, values["rotor_reference_speed_hz"], times,
                             speeds) if orders else None

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
        if "rotor_tachometer" in changes:
            self._tachometer = bool(changes["rotor_tachometer"])
        if any(name in changes for name in ROTOR_PARAMS):
            self._apply_rotor(startup)
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

    def _apply_rotor(self, startup: bool) -> None:
        """Rebuild the rotor from the parameters (checked in on-set): its phase restarts."""
        values = self.params.values()
        unpaired = rotor_unpaired(values)
        if unpaired:
            self.get_logger().warn(unpaired)
        if startup:
            return                      # the plant's shaker is built with it
        self.plant.shaker.rotor = self._make_rotor(values)

    # ------------------------------------------------------------------ state for the loop
    @property
    def sample(self) -> int:
        """The current sample (published or about to be, its commands awaited)."""
        return self.arbiter.sample

    @property
    def lockstep_timeout_s(self) -> float:
        """Longest wait (s, wall) for the commands of one sample in lockstep."""
        return self._lockstep_timeout_s

    def held(self) -> bool:
        """True while the lockstep breakpoint ``hold_at_time_s`` stops the loop here."""
        hold = self._hold_at_time_s
        return self.mode == "lockstep" and hold >= 0.0 and self.sample >= round(hold * self.fs)

    def commands_ready(self) -> bool:
        """Lockstep: every waited controller answered the current sample."""
        return self.arbiter.ready(self._timeout_samples)

    def unanswered(self) -> list[str]:
        """Expected controllers that did not answer the current sample (handshake)."""
        return self.arbiter.unanswered()

    # ------------------------------------------------------------------ commands
    def _on_command(self, name: str, msg: Float64MultiArray | bytes) -> None:
        topic = self.topics[name]
        sample = receive_strut_sample(msg, self.get_logger(), topic)
        if sample is None:
            self.arbiter.refuse(name)
            return
        refusal = self.arbiter.offer(name, sample.values, sample.index, sample.run,
                                     time.perf_counter())
        if refusal is not None and refusal.invalid:
            self.get_logger().warn(f"{topic}: refused command for sample {sample.index} "
                                   f"({refusal}) at sample {self.sample}",
                                   throttle_duration_sec=1.0)

    def refresh_connections(self) -> None:
        """Update which command streams are connected (graph, or a recent command)."""
        self.arbiter.refresh_connections(
            {name: self.count_publishers(topic) for name, topic in self.topics.items()},
            self._timeout_samples)

    # ------------------------------------------------------------------ loop steps
    def sensor_time_s(self) -> float:
        """Sim time (s) at which the current sample's sensors were read: (n + 1) / fs.

        The plant has advanced n + 1 steps when sample n is published (the sensors of
        sample n are read at the end of step n).
        """
        return self.plant.sample_index * self.plant.dt_sample_s

    def publish_sample(self) -> None:
        """Publish /clock, the tachometer and the sensors of the current sample."""
        n, sensors, run = self.sample, self._sample_pending, self.run_id
        self._offer = (clock_cdr(n, self.fs), self._pub_accel.encode(sensors.accel_m_s2, n, run),
                       self._pub_eddy.encode(sensors.eddy_m, n, run))
        self._reference_msg = self._tachometer_message(n)
        self.offer_again(repeated=False)
        self.arbiter.published(time.perf_counter())
        if n % FREQUENCIES_EVERY_SAMPLES == 0:
            self._pub_frequencies.publish(make_vector_array(
                self.plant.shaker.frequencies_hz(self.sensor_time_s()), n, run))

    def _tachometer_message(self, n: int) -> Float64MultiArray | None:
        """/pph/reference_frequency for sample n (rotor speed, Hz), None when off."""
        rotor = self.plant.shaker.rotor
        if not self._tachometer or rotor is None:
            return None
        return make_vector_array([float(rotor.speed_hz(self.sensor_time_s()))], n, self.run_id)

    def offer_again(self, repeated: bool = True) -> None:
        """Publish the current sample's /clock, tachometer and sensors (again: the same)."""
        clock, accel, eddy = self._offer
        if self._reference_msg is not None:
            self._pub_reference.publish(self._reference_msg)
        self._pub_clock(clock)
        self._pub_accel.publish_bytes(accel)
        self._pub_eddy.publish_bytes(eddy)
        if repeated:
            self.arbiter.offered_again()

    def timed_out(self) -> None:
        """Lockstep gave up waiting for the current sample's commands."""
        self.arbiter.timed_out()
        self.refresh_connections()

    def restart_stats(self) -> None:
        """Start the loop statistics afresh (at the start of the loop, after the handshake)."""
        self.arbiter.restart_stats(time.perf_counter())

    def apply_and_step(self) -> None:
        """Sum, saturate, publish the applied force and advance the plant one sample."""
        forces, newly_stale = self.arbiter.close_sample(self.mode == "lockstep",
                                                        self._timeout_samples)
        for name in newly_stale:
            self.get_logger().warn(f"{self.topics[name]}: no command for "
                                   f"{self._timeout_samples} samples, force set to zero")
        notch = forces["notch"]
        if self._test_sine_amplitude_n > 0.0:
            notch = notch + actuator_test_sine(self.sample, self._test_sine_frequency_hz,
                                               self._test_sine_amplitude_n, self.fs)
        applied = saturate_commands(notch, forces["pointing"], self.model.strut)
        self._pub_force.publish(applied, self.sample, self.run_id)
        self._sample_pending = self.plant.step(applied)
        self.arbiter.advance()
        if self.sample % int(self.fs) == 0:
            self.publish_diagnostics()

    def publish_diagnostics(self, held: bool = False) -> None:
        """Loop health and statistics on /diagnostics (``held``: at the breakpoint)."""
        values, warn, message = self.arbiter.report(time.perf_counter(),
                                                    self.mode == "lockstep")
        values.update({"mode": self.mode, "held": held, **self.readers.values(),
                       "fallback_samples": self.plant.fallback_samples,
                       "accel_clipped_samples": self.plant.accelerometers.clipped_samples})
        rotor = self.plant.shaker.rotor
        if rotor is not None:
            values["rotor_speed_hz"] = float(rotor.speed_hz(self.sensor_time_s()))
        self._pub_diag.publish(diagnostic_array(DRIVER_STATUS, warn, message, values,
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
        spinner.spin_once(timeout_sec=max(until - now, 0.0))
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
        if node.sample % 200 == 0:
            node.refresh_connections()
        node.apply_and_step()


def run_realtime(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Pace the loop at the sample rate on the wall clock, as hardware would.

    The clock starts once the expected controllers answered sample 0 (at most
    ``REALTIME_HANDSHAKE_S``), so a restarted driver is answered from its first samples.
    """
    period = 1.0 / node.fs
    wait_for_controllers(node, spinner, REALTIME_HANDSHAKE_S)
    start = time.perf_counter() - period      # sample 0's period was the handshake's
    if rclpy.ok():
        node.apply_and_step()      # sample 0 is out (and answered, unless the wait ran out)
    while rclpy.ok():
        node.publish_sample()
        deadline = start + (node.sample + 1) * period
        spinner.spin_once(timeout_sec=0.0)   # after an overrun: what is here is not late
        while (remaining := deadline - time.perf_counter()) > 0.0:
            spinner.spin_once(timeout_sec=remaining)
        if node.sample % 200 == 0:
            node.refresh_connections()
        node.apply_and_step()


def run_driver(node: PPHDriver, spinner: LoopSpinner) -> None:
    """Run the loop of the driver's ``clock_mode`` until shutdown, then report once more."""
    node.restart_stats()
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
