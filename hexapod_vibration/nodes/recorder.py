"""``pph_recorder``: record the contract topics into a rosbag2 bag (MCAP or sqlite3).

A stand-in for ``ros2 bag record`` on machines without rosbag2 (the PyPI set-up), and the
recorder the experiment runner starts. Subscriptions are raw: the CDR bytes are written as
received, taken from one persistent wait set (``ros.executors.LoopSpinner``) at most every
``BATCH_PERIOD_S``; rclpy's executor serves the timers and parameter services. Its
parameters (``bag_path``, ``storage``, ``run_record``; ``use_sim_time`` defaults to true
here) are listed by ``pph_recorder --help``.

The bag is what rosbag2 Jazzy writes (:mod:`hexapod_vibration.analysis.bag_recording`):
``<bag>/<bag>_0.mcap`` (or ``_0.db3``), ``metadata.yaml`` version 9 with each topic's
``offered_qos_profiles``; every loop message is stamped with its sample's sim time (n ms),
a sample already written on a topic is dropped and counted; what is written is on disk
within ``FLUSH_PERIOD_S``, so a killed recorder leaves a bag that ``analyze`` reads up to
its last flush.

Every second (wall time) it publishes its status on ``/diagnostics``: per recorded topic,
the messages written (``<topic> messages``), the publishers matched (``<topic>
publishers``), on the loop topics the duplicate samples dropped (``<topic> duplicates``) and
the highest sample written (``<topic> last sample``, -1: none), and its CPU budget. A
runner waits for every publisher it needs to be matched on the recorder's side before
starting the loop. SIGINT or SIGTERM stops it cleanly: messages already queued are
written, then the bag is closed and the message counts are logged, and it leaves the graph
(``ros.recording_loop.leave_graph``: the other nodes unmatch it at once).
"""

from __future__ import annotations

import sys
from datetime import datetime
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from hexapod_vibration import cli
from hexapod_vibration.analysis.bag_format import ACCEL_TOPIC, RUN_RECORD_KEY, STORAGE_PLUGINS
from hexapod_vibration.analysis.bag_recording import FLUSH_PERIOD_S, BagRecording, RecordingError
from hexapod_vibration.analysis.bag_writer import qos_from_rclpy
from hexapod_vibration.diagnostics_cdr import OK, WARN, encode_diagnostics_cdr
from hexapod_vibration.parameter_specs import PPH_RECORDER
from hexapod_vibration.ros.diagnostics import publish_status_periodically
from hexapod_vibration.ros.executors import loop_meter
from hexapod_vibration.ros.parameters import NodeParameters
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS
from hexapod_vibration.ros.rclpy_internals import parameter_overrides, take_serialized_batch
from hexapod_vibration.ros.recorded_topics import LOOP_TOPICS, RECORDED_TOPICS, RecordedTopic
from hexapod_vibration.ros.recording_loop import install_stop_flag, leave_graph, record

NODE_NAME = "pph_recorder"
MAX_BATCH = 500
"""Messages taken from one subscription per executor callback before others get their turn."""
class BagRecorder(Node):
    """Node writing the raw messages of :data:`RECORDED_TOPICS` into a rosbag2 bag."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, create the bag and subscribe.

        Args:
            **kwargs: Passed to ``rclpy.node.Node`` (e.g. ``context``).

        Raises:
            RecordingError: The bag cannot be created.
        """
        super().__init__(NODE_NAME, **kwargs)
        self._default_to_sim_time()
        params = NodeParameters(self, PPH_RECORDER)   # parameter_specs: bag_path, storage, ...
        params.serve()
        bag_path, storage, run_record = (params["bag_path"], params["storage"],
                                         params["run_record"])
        self.bag_path = Path(bag_path or datetime.now().strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))
        self.recording = BagRecording(
            self.bag_path, STORAGE_PLUGINS[storage],
            {RUN_RECORD_KEY: run_record} if run_record else {},
            [t.name for t in RECORDED_TOPICS], LOOP_TOPICS)
        self.meter = loop_meter()
        self._count = self.meter.counter(NODE_NAME)
        self._write_stage = self.meter.stage("recorder write")
        self._subscriptions_by_topic = {topic.name: self._subscribe(topic)
                                        for topic in RECORDED_TOPICS}
        self._status_publisher = self.create_publisher(DiagnosticArray, "/diagnostics",
                                                       DIAGNOSTICS_QOS)
        publish_status_periodically(self, self._publish_status)
        self.create_timer(FLUSH_PERIOD_S, self.recording.flush_if_due,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"recording {len(RECORDED_TOPICS)} topics into {self.bag_path}")

    def _default_to_sim_time(self) -> None:
        """Turn ``use_sim_time`` on unless it was given at start-up (CLI, params file)."""
        if "use_sim_time" not in parameter_overrides(self):
            self.set_parameters([Parameter("use_sim_time", value=True)])

    def _subscribe(self, topic: RecordedTopic) -> Subscription:
        """Subscribe (raw) to one topic; a callback writes every message already queued.

        The executor's per-callback cost (about 0.1 ms in rclpy) would cap the recorder
        below the loop's message rate: the callback takes the rest of the queue directly
        (as the LoopSpinner does for every recorded topic).
        """
        subscription: Subscription | None = None

        def on_message(data: bytes) -> None:
            self._write(topic, data)
            if subscription is not None:
                for queued in take_serialized_batch(subscription, MAX_BATCH):
                    self._write(topic, queued)

        subscription = self.create_subscription(topic.msg_class, topic.name, on_message,
                                                 topic.qos, raw=True)
        return subscription

    def _write(self, topic: RecordedTopic, data: bytes) -> None:
        """Write one serialized message (loop samples already written are dropped)."""
        written = self.recording.write(topic.name, topic.msgtype, data, self._now_ns,
                                       self._offered_qos)
        self.meter.lap(self._write_stage)
        if written and topic.name == ACCEL_TOPIC:
            self._count()

    def _now_ns(self) -> int:
        """The node clock (sim time under ``use_sim_time``), ns."""
        return self.get_clock().now().nanoseconds

    def _offered_qos(self, topic: str) -> list:
        """QoS profiles of the publishers matched on ``topic`` (rosbag2's offered profiles)."""
        try:
            infos = self.get_publishers_info_by_topic(topic)
        except (RuntimeError, ValueError):
            return []
        return [qos_from_rclpy(info.qos_profile) for info in infos
                if info.node_name != self.get_name()]

    @property
    def recorded_subscriptions(self) -> list[Subscription]:
        """The (raw) subscriptions of the recorded topics, one per topic."""
        return list(self._subscriptions_by_topic.values())

    @property
    def total(self) -> int:
        """Messages written so far, all topics."""
        return self.recording.total

    def status_values(self) -> dict[str, object]:
        """Health of the recording: per topic, messages written and publishers matched."""
        rec = self.recording
        values: dict[str, object] = {}
        for name, subscription in self._subscriptions_by_topic.items():
            values[f"{name} messages"] = rec.counts[name]
            values[f"{name} publishers"] = subscription.get_publisher_count()
            if name in rec.duplicates:
                values[f"{name} duplicates"] = rec.duplicates[name]
                values[f"{name} last sample"] = rec.last_sample(name)
        if rec.open:
            values["flushed messages"] = rec.flushed
        values.update(self.meter.report())
        return values

    def _publish_status(self) -> None:
        """Publish the recording's status on ``/diagnostics`` (every second of wall time)."""
        rec = self.recording
        sec, nanosec = divmod(self._now_ns(), 1_000_000_000)
        state = "recording" if rec.open else "closed"
        message = f"{state} {rec.total} messages into {self.bag_path}"
        self._status_publisher.publish(encode_diagnostics_cdr(
            OK if rec.open else WARN, f"{self.get_name()}: bag", message, str(self.bag_path),
            self.status_values(), sec, nanosec))

    def close_bag(self) -> None:
        """Close the bag (writes metadata.yaml) and log the message counts; idempotent."""
        summary = self.recording.close()
        if summary is not None:
            self.get_logger().info(f"closed {self.bag_path}: {self.total} messages ({summary})")


def run(args: list[str] | None = None) -> int:
    """Record until SIGINT/SIGTERM; return the process exit code."""
    stop = install_stop_flag()
    if cli.stop_requested() is not None:     # it came during the imports
        return cli.interrupted_exit_code()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        recorder = BagRecorder()
    except (RecordingError, ValueError) as err:
        print(f"{NODE_NAME}: error: {err}", file=sys.stderr)
        return 2
    record(recorder, stop)          # the bag is closed: nothing is lost from here on
    code = 128 + stop.signum if stop.is_set() else 0
    leave_graph(recorder, lambda: cli.exit_now(code))
    return code


def main(args: list[str] | None = None) -> None:
    """Entry point of ``pph_recorder``: exit 0, 2 (bad parameter), 130/143 (SIGINT/SIGTERM)."""
    args = cli.node_command_line(NODE_NAME, (NODE_NAME,), args)
    cli.exit_now(run(args))


if __name__ == "__main__":
    main()
