"""``notch_controller``: six decentralized Adaptive Notch Cancellers (the paper's algorithm).

A thin rclpy shell over :class:`~hexapod_vibration.core.control.notch_supervisor.NotchSupervisor`
(everything numerical, every decision). Each ``/pph/accel`` sample goes to the supervisor and
its command out on ``/pph/notch_command`` with the same index (an older sample skipped for a
newer one is only observed); parameters are checked in the on-set callback and applied in
the post-set one. Out: the weights (100 Hz), each tone's frequency now, the predicted
sensitivity after each identification (transient local), ``/diagnostics``. In, besides:
the tachometer (``/pph/reference_frequency``, served before ``/pph/accel``) and the driver's
held commands (``/pph/notch_held``, for the identification) and stand-ins (``/pph/stand_ins``,
for the divergence guard); out to it, every 10 samples while it listens, the next
200 samples' commands (``/pph/notch_forecast``).
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from hexapod_vibration.cdr import (
    UnsupportedCdr,
    decode_strut_cdr,
    encode_vector_cdr,
    encode_weights_cdr,
)
from hexapod_vibration.contract import (
    DIAGNOSTICS_EVERY_SAMPLES,
    DIAGNOSTICS_PHASE_SAMPLES,
    FORECAST_PHASE_SAMPLES,
    FREQUENCIES_EVERY_SAMPLES,
    NOTCH_FORECAST_TOPIC,
    NOTCH_FREQUENCIES_TOPIC,
    NOTCH_SENSITIVITY_TOPIC,
    NOTCH_STATUS,
    REFERENCE_FREQUENCY_TOPIC,
    SAMPLE_RATE_HZ,
    InvalidStrutMessage,
)
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.loop.idle_work import IdleWork
from hexapod_vibration.core.loop.signal_ranges import SignalRanges
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.parameter_specs import NOTCH_CONTROLLER
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.analysis_worker import start_analysis_worker
from hexapod_vibration.ros.command_forecasts import ForecastPublisher, notch_rows
from hexapod_vibration.ros.diagnostics import diagnostic_array, publish_status_periodically
from hexapod_vibration.ros.executors import LoopSpinner, loop_meter
from hexapod_vibration.ros.held_reports import (
    subscribe_held_reports,
    subscribe_stand_in_reports,
)
from hexapod_vibration.ros.matching import MatchedReaders
from hexapod_vibration.ros.messages import (
    ControllerLoopPort,
    StrutArrayPublisher,
    create_loop_subscription,
    make_table_array,
)
from hexapod_vibration.ros.node_runner import run_node
from hexapod_vibration.ros.parameters import NodeParameters
from hexapod_vibration.ros.qos import (
    DIAGNOSTICS_QOS,
    LATCHED_QOS,
    LOOP_PUBLISHER_QOS,
    OBSERVED_LOOP_QOS,
)
from hexapod_vibration.ros.rclpy_internals import serialized_publish

WEIGHTS_EVERY_SAMPLES = 10
"""Samples between two /pph/notch_weights messages (100 Hz)."""
DIAGNOSTICS_PHASE = DIAGNOSTICS_PHASE_SAMPLES["notch_controller"]
SETTINGS = frozenset(NotchConfig.__dataclass_fields__)
"""Parameters that are notch settings (the rest, e.g. executor, are the node's own)."""
LOOP_WAIT_S = 0.001
"""Longest wait (s) for a loop message between two looks at a setting change's worker job."""


class NotchControllerNode(Node):
    """Adaptive Notch Canceller node: parameters and messages in and out of the supervisor."""

    def __init__(self) -> None:
        """Declare parameters, build the supervisor, wire topics and the identify service."""
        super().__init__("notch_controller")
        self.params = NodeParameters(self, NOTCH_CONTROLLER)
        self.fs = SAMPLE_RATE_HZ
        values = self.params.values()
        model = load_model_config(config_path("pph_model.yaml"))
        config = NotchConfig().replaced(self._settings_with_pipeline(values))
        z_row = np.linalg.inv(model.geometry.top_jacobian)[2]       # the z axis, as CoreLoop
        self._worker = self._start_worker(values["identification_analysis"])
        try:
            self.supervisor = NotchSupervisor(config, self.fs, output_weights=z_row,
                                              analysis_worker=self._worker)
        except ValueError:             # settings refused as a whole: no worker left behind
            self._stop_worker()
            raise
        accel_range = SignalRanges.from_model(model).accel_m_s2      # the accelerometers' +-2 g
        self.readers = MatchedReaders(self.publish_diagnostics)
        arrays = {topic: self.readers.publisher(self, Float64MultiArray, topic, LOOP_PUBLISHER_QOS)
                  for topic in ("/pph/notch_command", "/pph/notch_weights",
                                NOTCH_FREQUENCIES_TOPIC)}
        self.port = ControllerLoopPort("/pph/accel", accel_range, StrutArrayPublisher(
            arrays["/pph/notch_command"]), self.get_logger(), counts_gaps=False)
        self._pub_w = serialized_publish(arrays["/pph/notch_weights"])   # CDR bytes
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        publish_status_periodically(self, self.publish_diagnostics)
        self._pub_frequencies = serialized_publish(arrays[NOTCH_FREQUENCIES_TOPIC])
        self.idle_work = IdleWork()                   # run by the loop's spinner when idle
        self._forecasts = ForecastPublisher(            # for late samples
            self, NOTCH_FORECAST_TOPIC, FORECAST_PHASE_SAMPLES["notch_controller"],
            notch_rows(self.supervisor), self.idle_work, self.port.last_acted)
        self._pub_sensitivity = self.create_publisher(
            Float64MultiArray, NOTCH_SENSITIVITY_TOPIC, LATCHED_QOS)
        self._published_sensitivity: object | None = None
        # The tachometer is a loop topic too, served first: the driver publishes sample n's
        # reference before its sensors, so it is taken before sample n is stepped.
        reference = create_loop_subscription(self, REFERENCE_FREQUENCY_TOPIC, self._on_reference)
        accel = create_loop_subscription(self, "/pph/accel", self._on_accel, OBSERVED_LOOP_QOS)
        self.loop_subscriptions = [reference, accel]
        self.latest_only_subscriptions = list(self.loop_subscriptions)  # stale samples: skipped
        self.skipped_message_callbacks = {accel: self.port.hold_skipped}
        run, delay = (lambda: self.port.sequence.run), values["command_delay_samples"]
        self.loop_subscriptions += [
            subscribe_held_reports(self, run, self.supervisor.note_held),
            subscribe_stand_in_reports(self, run, lambda rows, covered: (
                self.supervisor.note_stand_ins(rows, covered, delay)))]
        self.meter = loop_meter()
        self._count = self.meter.counter("notch_controller")
        self._stage = {name: self.meter.stage(f"notch {name}")
                       for name in ("decode", "control", "publish", "report")}
        self.create_service(Trigger, "~/identify", self._on_identify)
        self.params.serve(check=self._check_parameters, apply=self._apply_parameters)
        config = self.supervisor.config
        self.get_logger().info(f"notch controller up: tones {list(config.tone_frequencies_hz)}"
                               f" Hz, mu {config.mu:g}, {config.adaptation}")

    # ------------------------------------------------------------------ parameters
    @staticmethod
    def _settings_with_pipeline(values: dict) -> dict:
        """The notch settings among ``values``, the loop delay grown by the command delay.

        The driver applies this node's answers ``command_delay_samples`` later, so the loop's
        delay in the stability bound grows by as much. ValueError beyond the bound's range.
        """
        settings = {k: v for k, v in values.items() if k in SETTINGS}
        base, delay = settings["loop_delay_samples"], values["command_delay_samples"]
        highest = NOTCH_CONTROLLER["loop_delay_samples"].high
        if base + delay > highest:
            raise ValueError(f"loop_delay_samples {base:g} + command_delay_samples {delay} = "
                             f"{base + delay:g} samples of loop delay, more than {highest:g}")
        settings["loop_delay_samples"] = base + delay
        return settings

    def _start_worker(self, place: str) -> ProcessPoolExecutor | None:
        """The analysis worker of ``identification_analysis: process`` (None: the loop's).

        One the OS cannot start is said in one line, and the loop's thread analyses.
        """
        if place != "process":
            return None
        try:
            return start_analysis_worker()
        except OSError as exc:
            self.get_logger().warning(f"identification_analysis process: no worker ({exc}); "
                                      "the loop's thread analyses")
            return None

    def serve_loop_with(self, spinner: LoopSpinner) -> None:
        """With an analysis worker, a setting change's Nyquist limit and mu policy run on it.

        The check (the on-set callback) of a change of tones or mode while G(f) is known
        waits for its limit serving the 1 kHz loop meanwhile (``executor: waitset`` only:
        the loop's own wait set); the apply leaves the policy's choice to the worker
        (``supervisor/background_choice.py``).
        """
        if self._worker is not None and spinner.fast:
            self.supervisor.serve_while_waiting(lambda: spinner.serve_loop(LOOP_WAIT_S))

    def _stop_worker(self) -> None:
        """Stop the analysis worker, if any, after a job in progress: no resource left."""
        if self._worker is not None:
            self._worker.shutdown(wait=True, cancel_futures=True)

    def destroy_node(self) -> None:
        """Stop the analysis worker, then the node."""
        self._stop_worker()
        super().destroy_node()

    def _check_parameters(self, values: dict, changed: frozenset) -> str:
        """Validate only: the supervisor checks the changed settings as a whole."""
        try:
            self.supervisor.check({k: values[k] for k in changed if k in SETTINGS})
        except ValueError as exc:
            return str(exc)
        return ""

    def _apply_parameters(self, changes: dict) -> None:
        """Apply a set that passed validation (post-set)."""
        self.supervisor.apply({k: v for k, v in changes.items() if k in SETTINGS})
        self._report()

    def _on_identify(self, _request, response):
        try:
            response.message = self.supervisor.start_identification()
            response.success = True
        except ValueError as exc:
            response.success, response.message = False, str(exc)
        self._report()
        return response

    # ------------------------------------------------------------------ loop
    def _on_accel(self, msg: Float64MultiArray | bytes) -> None:
        meter, stage = self.meter, self._stage
        sample = self.port.receive(msg)       # decoded, in range, in sequence, or None
        meter.lap(stage["decode"])
        if sample is None:
            return
        if sample.new_run:
            self.supervisor.reset_run(sample.index)
        for skipped in sample.skipped:                  # recorded, not answered
            self.supervisor.observe(skipped.index, skipped.values)
        command = self.supervisor.step(sample.index, sample.values)
        meter.lap(stage["control"])
        if command is None:
            return
        self.port.answer(command, sample)
        self._forecasts.after(sample.index)
        meter.lap(stage["publish"])
        self._count()
        index = sample.index
        if index % WEIGHTS_EVERY_SAMPLES == 0:
            self._pub_w(encode_weights_cdr(self.supervisor.canceller.weights, index))
        if index % FREQUENCIES_EVERY_SAMPLES == 0:
            self._pub_frequencies(encode_vector_cdr(self.supervisor.tone_estimates_hz,
                                                    index, sample.run))
        if index % DIAGNOSTICS_EVERY_SAMPLES == DIAGNOSTICS_PHASE:
            self.publish_diagnostics()
        self._report()
        meter.lap(stage["report"])

    def _on_reference(self, msg: bytes) -> None:
        """A tachometer value (Hz) for a loop sample: to the supervisor, or refused (logged)."""
        try:
            reference = decode_strut_cdr(bytes(msg), count=1)
        except (InvalidStrutMessage, UnsupportedCdr) as exc:
            self.get_logger().warn(f"{REFERENCE_FREQUENCY_TOPIC}: rejected message ({exc})",
                                   throttle_duration_sec=1.0)
            return
        frequency_hz = float(reference.values[0])
        run = self.port.sequence.run
        if not 0.0 <= frequency_hz < self.fs / 2.0:
            self.get_logger().warn(f"{REFERENCE_FREQUENCY_TOPIC}: rejected {frequency_hz:g} Hz "
                                   f"(must be in [0, {self.fs / 2.0:g}) Hz)",
                                   throttle_duration_sec=1.0)
        elif reference.run is None or run is None or reference.run == run:
            self.supervisor.set_reference_frequency(frequency_hz, reference.index)

    def _publish_sensitivity(self) -> None:
        """The prediction of the last identification, once (``/pph/notch_sensitivity``)."""
        prediction = self.supervisor.sensitivity
        if prediction is None or prediction is self._published_sensitivity:
            return
        self._published_sensitivity = prediction
        self._pub_sensitivity.publish(make_table_array(prediction.table_db(),
                                                       max(self.supervisor.last_sample, 0)))

    def _report(self) -> None:
        """Log what the supervisor did, mirror a setting it changed, publish the change."""
        events = self.supervisor.drain_events()
        if not events:
            return
        self._publish_sensitivity()
        logger = self.get_logger()
        for event in events:
            # One call site per severity: rclpy refuses a call site whose severity changes.
            if event.level == "error":
                logger.error(event.message)
            elif event.level == "warn":
                logger.warning(event.message)
            else:
                logger.info(event.message)
            if event.parameter is not None:
                self.set_parameters([Parameter(event.parameter[0], value=event.parameter[1])])
        self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """State, counters (gaps: the supervisor's) and CPU budget on /diagnostics."""
        status = {**self.supervisor.status(), **self.port.diagnostics(),
                  **self.readers.values(), **self.meter.report()}
        self._pub_diag.publish(diagnostic_array(NOTCH_STATUS, bool(status["invalid"]),
                                                status["state"], status,
                                                self.supervisor.last_sample))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration notch_controller``."""
    run_node("notch_controller", NotchControllerNode, args=args)


if __name__ == "__main__":
    main()
