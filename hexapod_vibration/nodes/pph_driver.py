"""``pph_driver``: the simulated Precision Pointing Hexapod as a ROS 2 node.

Every sample n (1 kHz) it publishes ``/clock`` (n ms of sim time), ``/pph/accel`` and
``/pph/eddy`` (in-band sample index n and the run's identity), waits for the commands of
sample n (lockstep) or until the sample's wall-clock deadline (realtime) (the pacing is in
:mod:`~hexapod_vibration.nodes.driver_loop`), applies ``/pph/notch_command`` and
``/pph/pointing_command`` through :class:`~hexapod_vibration.core.model.actuation.
ActuatedPlant` (summed, saturated, held), publishes ``/pph/actuator_force`` (what is applied
over [n, n+1)) and advances the plant. Which command of each stream applies (the first valid
one per sample; zero force once a stream is older than ``command_timeout_samples``, reached
over ``command_fade_samples``) is
decided by :class:`~hexapod_vibration.core.loop.command_arbiter.CommandArbiter`. Health, loop
statistics and the CPU budget go to ``/diagnostics`` once per simulated second.

With ``rotor_tachometer`` on, the rotor's speed for sample n (Hz) goes out on
``/pph/reference_frequency`` before the sample's sensors; the true frequency of every sounding
tone goes out on ``/pph/disturbance_frequencies`` every ``FREQUENCIES_EVERY_SAMPLES`` samples.
A realtime driver applies a controller's forecast (``/pph/notch_forecast``,
``/pph/pointing_forecast``) for a sample whose command is late, and reports the notch
commands it held (``/pph/notch_held``) and the samples where a stand-in no controller
computed went in (``/pph/stand_ins``): :mod:`~hexapod_vibration.nodes.driver_reports`.
"""

from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    DIAGNOSTICS_EVERY_SAMPLES,
    DIAGNOSTICS_PHASE_SAMPLES,
    DRIVER_STATUS,
    FORECAST_TOPICS,
    FREQUENCIES_EVERY_SAMPLES,
    new_run_id,
)
from hexapod_vibration.core.loop.command_arbiter import CommandArbiter
from hexapod_vibration.core.loop.signal_ranges import SignalRanges
from hexapod_vibration.core.model.actuation import ActuatedPlant
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import PPHPlant
from hexapod_vibration.nodes.driver_loop import run_driver
from hexapod_vibration.nodes.driver_outputs import DriverOutputs
from hexapod_vibration.nodes.driver_reports import DriverReports
from hexapod_vibration.nodes.driver_settings import DriverSettings
from hexapod_vibration.parameter_specs import LOCKSTEP_STREAMS, PPH_DRIVER
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.command_forecasts import subscribe_forecasts
from hexapod_vibration.ros.diagnostics import diagnostic_array
from hexapod_vibration.ros.executors import loop_meter
from hexapod_vibration.ros.messages import create_loop_subscription, receive_strut_sample
from hexapod_vibration.ros.node_runner import run_node
from hexapod_vibration.ros.qos import COMMAND_QOS, DIAGNOSTICS_QOS

DIAGNOSTICS_PHASE = DIAGNOSTICS_PHASE_SAMPLES["pph_driver"]


class PPHDriver(Node):
    """Simulated hexapod: plant stepping, sensor publishing, commands through the arbiter."""

    def __init__(self) -> None:
        """Declare parameters, build the plant, create publishers and subscriptions."""
        super().__init__("pph_driver")
        self.settings = DriverSettings(self, PPH_DRIVER)
        values = self.settings.values()
        self.mode = values["clock_mode"]
        model = load_model_config(values["model_file"] or config_path("pph_model.yaml"))
        self.model = model if values["nonlinear"] else model.linear()
        self.fs = self.model.simulation.sample_rate_hz
        plant = PPHPlant(self.model, shaker=self.settings.make_shaker(self.model, values["seed"]),
                         seed=values["seed"])
        self.actuated = ActuatedPlant(plant, self.model.strut, self.fs)
        self.settings.bind(self.actuated)
        self.run_id = new_run_id()
        self.arbiter = CommandArbiter(LOCKSTEP_STREAMS, self.settings.expected, self.run_id,
                                      SignalRanges.from_model(self.model).command_n,
                                      latency_stream="notch",
                                      delay_samples=values["command_delay_samples"])
        self.topics = {name: f"/pph/{name}_command" for name in LOCKSTEP_STREAMS}
        self.outputs = DriverOutputs(self, self.fs,
                                     lambda: self.publish_diagnostics(held=self.held()),
                                     defer_force=self.mode == "realtime")
        self.reports = DriverReports(self) if self.mode == "realtime" else None
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.loop_subscriptions = [
            create_loop_subscription(self, topic, lambda msg, n=name: self._on_command(n, msg),
                                     COMMAND_QOS)
            for name, topic in self.topics.items()]
        if self.mode == "realtime":         # lockstep waits for every command: none is late
            self.loop_subscriptions += [subscribe_forecasts(
                self, FORECAST_TOPICS[name], lambda rows, first, run, n=name:
                self.arbiter.forecast(n, first, rows, run)) for name in self.topics]
        self.meter = loop_meter()
        self._count = self.meter.counter("pph_driver")
        self._stage = {name: self.meter.stage(f"driver {name}")
                       for name in ("commands", "plant", "publish", "report")}
        self.get_logger().info(
            f"PPH driver up: {self.mode}, {'nonlinear' if self.model is model else 'linear'}"
            f" plant, {self.fs:.0f} Hz, watchdog {self.settings.timeout_samples} samples, "
            f"command delay {self.arbiter.delay} samples, "
            f"run {self.run_id}")

    # ------------------------------------------------------------------ state for the loop
    @property
    def sample(self) -> int:
        """The current sample (published or about to be, its commands awaited)."""
        return self.arbiter.sample

    @property
    def lockstep_timeout_s(self) -> float:
        """Longest wait (s, wall) for the commands of one sample in lockstep."""
        return self.settings.lockstep_timeout_s

    def held(self) -> bool:
        """True while the breakpoint ``hold_at_time_s`` stops the loop here (any clock mode).

        Realtime: the start breakpoint (0) starts the clock when the graph (a recorder) is
        ready; a later one stops the clock until it is moved on.
        """
        hold = self.settings.hold_at_time_s
        return hold >= 0.0 and self.sample >= round(hold * self.fs)

    def paused(self, held: bool) -> None:
        """The loop stops at (``held``) or leaves a breakpoint: its statistics skip the pause."""
        (self.arbiter.pause if held else self.arbiter.resume)(time.perf_counter())

    def commands_ready(self) -> bool:
        """Lockstep: every waited controller answered the current sample."""
        return self.arbiter.ready(self.settings.timeout_samples)

    def answered(self) -> bool:
        """Realtime: every waited controller answered the newest sample (nothing expected)."""
        return self.arbiter.answered(self.settings.timeout_samples)

    def unanswered(self) -> list[str]:
        """Expected controllers that did not answer the current sample (handshake)."""
        return self.arbiter.unanswered()
    def sensor_time_s(self) -> float:
        """Sim time (s) at which the current sample's sensors were read: (n + 1) / fs."""
        plant = self.actuated.plant
        return plant.sample_index * plant.dt_sample_s

    # ------------------------------------------------------------------ commands
    def _on_command(self, name: str, msg: Float64MultiArray | bytes) -> None:
        topic = self.topics[name]
        sample = receive_strut_sample(msg, self.get_logger(), topic)
        if sample is None:
            self.arbiter.refuse(name)
        else:
            refusal = self.arbiter.offer(name, sample.values, sample.index, sample.run,
                                         time.perf_counter())
            if refusal is None and self.reports is not None and sample.index is not None:
                self.reports.answered(name, sample.index, sample.values)
            elif refusal is not None and refusal.invalid:
                self.get_logger().warn(f"{topic}: refused command for sample {sample.index} "
                                       f"({refusal}) at sample {self.sample}",
                                       throttle_duration_sec=1.0)
        self.meter.lap(self._stage["commands"])

    def refresh_connections(self) -> None:
        """Update which command streams are connected (graph, or a recent command)."""
        self.arbiter.refresh_connections(
            {name: self.count_publishers(topic) for name, topic in self.topics.items()},
            self.settings.timeout_samples)

    # ------------------------------------------------------------------ loop steps
    def publish_sample(self) -> None:
        """Publish /clock, the tachometer and the sensors of the current sample."""
        n, run, plant = self.sample, self.run_id, self.actuated.plant
        rotor = plant.shaker.rotor
        reference = (float(rotor.speed_hz(self.sensor_time_s()))
                     if self.settings.tachometer and rotor is not None else None)
        self.outputs.offer(n, run, self.actuated.pending, reference)
        self.arbiter.published(time.perf_counter())
        if n % FREQUENCIES_EVERY_SAMPLES == 0:
            self.outputs.frequencies(plant.shaker.frequencies_hz(self.sensor_time_s()), n, run)
        self.meter.lap(self._stage["publish"])

    def offer_again(self) -> None:
        """Publish the current sample's /clock, tachometer and sensors again (lockstep)."""
        self.outputs.offer_again()
        self.arbiter.offered_again()

    def timed_out(self) -> None:
        """Lockstep gave up waiting for the current sample's commands."""
        self.arbiter.timed_out()
        self.refresh_connections()

    def restart_stats(self) -> None:
        """Start the loop statistics afresh (at the start of the loop, after the handshake)."""
        self.arbiter.restart_stats(time.perf_counter())

    def apply_and_step(self) -> None:
        """Apply the current sample's commands, publish the applied force, advance one sample."""
        timeout, fade = self.settings.timeout_samples, self.settings.fade_samples
        forces, newly_stale = self.arbiter.close_sample(self.mode == "lockstep", timeout, fade)
        if self.reports is not None:
            self.reports.note(self.arbiter, forces, self.run_id)
        for name in newly_stale:
            self.get_logger().warn(f"{self.topics[name]}: no command for {timeout} samples "
                                   f"(nor a forecast), force falling to zero over {fade} "
                                   "samples")
        applied = self.actuated.apply(self.sample, forces["notch"], forces["pointing"])
        self.meter.lap(self._stage["plant"])
        self.outputs.force(applied, self.sample, self.run_id)
        self.meter.lap(self._stage["publish"])
        self.arbiter.advance()
        self._count()
        if self.sample % DIAGNOSTICS_EVERY_SAMPLES == DIAGNOSTICS_PHASE:
            self.publish_diagnostics()
            self.meter.lap(self._stage["report"])

    def publish_diagnostics(self, held: bool = False) -> None:
        """Loop health, statistics and CPU budget on /diagnostics (``held``: at the breakpoint)."""
        values, warn, message = self.arbiter.report(time.perf_counter(),
                                                    self.mode == "lockstep")
        plant = self.actuated.plant
        values.update({"mode": self.mode, "held": held, **self.outputs.readers.values(),
                       "fallback_samples": plant.fallback_samples, "plant_kernels": plant.kernels,
                       "accel_clipped_samples": plant.accelerometers.clipped_samples,
                       **self.meter.report()})
        if self.reports is not None:
            values["stand_in_samples"] = self.reports.stand_in_log.stood_in
        if plant.shaker.rotor is not None:
            values["rotor_speed_hz"] = float(plant.shaker.rotor.speed_hz(self.sensor_time_s()))
        self._pub_diag.publish(diagnostic_array(DRIVER_STATUS, warn, message, values,
                                                self.sample))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration pph_driver``."""
    run_node("pph_driver", PPHDriver, run_driver, args=args)


if __name__ == "__main__":
    main()
