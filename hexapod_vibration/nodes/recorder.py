"""``pph_recorder``: record the contract topics into a rosbag2 bag (MCAP or sqlite3).

A stand-in for ``ros2 bag record`` on machines without rosbag2 (the PyPI set-up), and the
recorder the experiment runner starts. Subscriptions are raw: the serialized CDR bytes
are written to the bag as received, with no deserialization or re-serialization, taken
from one persistent wait set (``ros.executors.LoopSpinner``; rclpy's executor serves the
timers and parameter services every 50 ms).

Parameters (read-only, set at start-up):
    bag_path (string): bag directory to create; default ``rosbag2_<date>-<time>`` in the
        current directory. An existing directory is never overwritten.
    storage (string): ``mcap`` (default) or ``sqlite3``.
    run_record (string): JSON written into ``metadata.yaml`` ``custom_data`` under
        ``hexapod_vibration.run`` (the experiment runner's record of its run); default none.
    use_sim_time (bool): default **true** here, so messages without a sample index are
        stamped with the sim time of ``/clock`` (0 until the first ``/clock`` message).

The bag is what rosbag2 Jazzy writes: ``<bag>/<bag>_0.mcap`` (or ``_0.db3``),
``metadata.yaml`` version 9 with ``ros_distro: jazzy`` and each topic's
``offered_qos_profiles`` (the QoS of the publishers the recorder matched). Every loop
message (``sample:<n>`` in band) is stamped with its sample's sim time, n ms, so
``ros2 bag play`` and plotting tools see the loop's own time base; a sample already written
on a topic is not written again (the lockstep handshake re-offers sample 0), and is counted.

Crash safety: a provisional ``metadata.yaml`` (``custom_data`` marks the recording open
and holds the run record) is written when recording starts; MCAP chunks are closed and
flushed at least every ``FLUSH_PERIOD_S`` and sqlite3 runs in write-ahead-log mode,
committed at least every ``FLUSH_PERIOD_S`` and every ``COMMIT_EVERY`` messages. A killed
recorder therefore leaves a bag that ``analyze`` reads up to its last flush
(:mod:`hexapod_vibration.analysis.recovery`).

Every second (wall time) it publishes its status on ``/diagnostics``: per recorded topic,
the messages written (``<topic> messages``), the publishers matched
(``<topic> publishers``) and the duplicate samples dropped (``<topic> duplicates``). A
runner waits for every publisher it needs to be matched on the recorder's side before
starting the loop: a publisher's own subscription count can become non-zero before the
recorder is ready to receive, and samples sent then are lost to the recording.

SIGINT or SIGTERM stops it cleanly: messages already queued are written, then the bag is
closed (``metadata.yaml`` written) and the message counts are logged.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterEvent
from rclpy.clock import Clock, ClockType
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2.errors import WriterError
from rosgraph_msgs.msg import Clock as ClockMessage
from std_msgs.msg import Float64MultiArray

from hexapod_vibration import cli
from hexapod_vibration.analysis.bag_io import (
    FREQUENCY_TOPICS,
    RUN_RECORD_KEY,
    SENSITIVITY_TOPIC,
    STORAGE_PLUGINS,
    STRUT_TOPICS,
    WEIGHTS_TOPIC,
    sample_index_of_cdr,
    typestore,
)
from hexapod_vibration.analysis.bag_writer import JazzyWriter, qos_from_rclpy, stamp_of_cdr
from hexapod_vibration.parameter_specs import PPH_RECORDER
from hexapod_vibration.ros.diagnostics import publish_status_periodically
from hexapod_vibration.ros.executors import LoopSpinner
from hexapod_vibration.ros.parameters import NodeParameters
from hexapod_vibration.ros.qos import (
    DIAGNOSTICS_QOS,
    LATCHED_QOS,
    PARAMETER_EVENTS_QOS,
    RECORDER_CLOCK_QOS,
    RECORDER_QOS,
)
from hexapod_vibration.ros.rclpy_internals import parameter_overrides, take_serialized_batch

NODE_NAME = 'pph_recorder'
MAX_BATCH = 500
"""Messages taken from one subscription per wake-up before others get their turn."""
DRAIN_IDLE_SPINS = 3
"""Consecutive idle spins (each up to DRAIN_SPIN_S) that end the drain at shutdown."""
DRAIN_SPIN_S = 0.05
DRAIN_MAX_S = 10.0
"""Upper bound (s) of the drain at shutdown, reached only if publishers keep publishing
(a recorder behind a fast lockstep loop may have a few seconds of messages queued)."""
FLUSH_PERIOD_S = 0.25
"""Longest time (s, wall) that written messages stay in memory before they are on disk."""
COMMIT_EVERY = 2000
"""sqlite3: messages per transaction at most (bounded loss and journal when killed)."""
LOOP_TOPICS = frozenset((*STRUT_TOPICS, WEIGHTS_TOPIC, *FREQUENCY_TOPICS))
"""Topics whose messages carry ``sample:<n>``: stamped n ms, one message per sample."""


@dataclass(frozen=True)
class RecordedTopic:
    """A topic the recorder subscribes to."""

    name: str
    msg_class: type
    msgtype: str
    qos: QoSProfile


RECORDED_TOPICS: tuple[RecordedTopic, ...] = (
    *(
        RecordedTopic(t, Float64MultiArray, 'std_msgs/msg/Float64MultiArray', RECORDER_QOS)
        for t in STRUT_TOPICS
    ),
    RecordedTopic(
        '/pph/notch_weights', Float64MultiArray, 'std_msgs/msg/Float64MultiArray', RECORDER_QOS
    ),
    *(
        RecordedTopic(t, Float64MultiArray, 'std_msgs/msg/Float64MultiArray', RECORDER_QOS)
        for t in FREQUENCY_TOPICS
    ),
    RecordedTopic(
        SENSITIVITY_TOPIC, Float64MultiArray, 'std_msgs/msg/Float64MultiArray', LATCHED_QOS
    ),
    RecordedTopic('/clock', ClockMessage, 'rosgraph_msgs/msg/Clock', RECORDER_CLOCK_QOS),
    RecordedTopic(
        '/diagnostics', DiagnosticArray, 'diagnostic_msgs/msg/DiagnosticArray', RECORDER_QOS
    ),
    RecordedTopic(
        '/parameter_events',
        ParameterEvent,
        'rcl_interfaces/msg/ParameterEvent',
        PARAMETER_EVENTS_QOS,
    ),
)


class RecorderError(RuntimeError):
    """The recorder cannot start (bag directory exists, bad parameter, unwritable path)."""


class BagRecorder(Node):
    """Node writing the raw messages of :data:`RECORDED_TOPICS` into a rosbag2 bag."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, create the bag and subscribe.

        Args:
            **kwargs: Passed to ``rclpy.node.Node`` (e.g. ``context``).

        Raises:
            RecorderError: The bag cannot be created.
        """
        super().__init__(NODE_NAME, **kwargs)
        self._default_to_sim_time()
        params = NodeParameters(self, PPH_RECORDER)   # parameter_specs: bag_path, storage, ...
        params.serve()
        bag_path, storage, run_record = (params['bag_path'], params['storage'],
                                         params['run_record'])
        self.bag_path = Path(bag_path or datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S'))
        custom = {RUN_RECORD_KEY: run_record} if run_record else {}
        self._writer = _open_writer(self.bag_path, STORAGE_PLUGINS[storage], custom)
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = {t.name: 0 for t in RECORDED_TOPICS}
        self.duplicates: dict[str, int] = dict.fromkeys(LOOP_TOPICS, 0)
        self._seen: dict[str, bytearray] = {t: bytearray() for t in LOOP_TOPICS}
        self._subscriptions_by_topic: dict[str, Subscription] = {}
        for topic in RECORDED_TOPICS:
            self._subscribe(topic)
        self._status_publisher = self.create_publisher(
            DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS
        )
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        publish_status_periodically(self, self._publish_status)
        self.create_timer(FLUSH_PERIOD_S, self._flush, clock=steady)
        self.get_logger().info(f'recording {len(RECORDED_TOPICS)} topics into {self.bag_path}')

    def _default_to_sim_time(self) -> None:
        """Turn ``use_sim_time`` on unless it was given at start-up (CLI, params file)."""
        if 'use_sim_time' not in parameter_overrides(self):
            self.set_parameters([Parameter('use_sim_time', value=True)])

    def _subscribe(self, topic: RecordedTopic) -> None:
        """Subscribe (raw) to one topic; each wake-up writes every message already queued."""
        subscription: Subscription | None = None

        def on_message(data: bytes) -> None:
            self._write(topic, data)
            if subscription is not None:
                self._write_queued(topic, subscription)

        subscription = self.create_subscription(
            topic.msg_class, topic.name, on_message, topic.qos, raw=True
        )
        self._subscriptions_by_topic[topic.name] = subscription

    def _write_queued(self, topic: RecordedTopic, subscription: Subscription) -> None:
        """Take and write up to MAX_BATCH queued messages without going through the executor.

        The executor's per-callback cost (about 0.1 ms in rclpy) would otherwise cap the
        recorder below the 6000+ messages/s of the loop; taking directly from the
        subscription handle, as the executor itself does, makes it about 10 us/message.
        """
        for data in take_serialized_batch(subscription, MAX_BATCH):
            self._write(topic, data)

    def _write(self, topic: RecordedTopic, data: bytes) -> None:
        """Write one serialized message, stamped by :meth:`_stamp`."""
        if self._writer is None:
            return
        stamp = self._stamp(topic.name, data)
        if stamp is None:
            return
        connection = self._connections.get(topic.name)
        if connection is None:  # created on the first message, like ros2 bag record
            connection = self._writer.add_connection(
                topic.name, topic.msgtype, typestore=typestore(),
                offered_qos_profiles=self._offered_qos(topic.name),
            )
            self._connections[topic.name] = connection
        self._writer.write(connection, stamp, data)
        self.counts[topic.name] += 1
        self._writer.flush_if_due(FLUSH_PERIOD_S, COMMIT_EVERY)

    def _stamp(self, topic: str, data: bytes) -> int | None:
        """Timestamp (ns) of a message; None for a loop sample already written.

        Loop topics: the sample's sim time (n ms); ``/clock`` and ``/diagnostics``: the sim
        time they carry; anything else (and a zero stamp): the node clock (sim time).
        """
        if topic in LOOP_TOPICS:
            sample = sample_index_of_cdr(data)
            seen = None if sample is None else _seen_before(self._seen[topic], sample)
            if seen:
                self.duplicates[topic] += 1
                return None
            if seen is not None:
                return sample * 1_000_000
        carried = stamp_of_cdr(topic, data)
        return carried if carried else self.get_clock().now().nanoseconds

    def _offered_qos(self, topic: str) -> list:
        """QoS profiles of the publishers matched on ``topic`` (rosbag2's offered profiles)."""
        try:
            infos = self.get_publishers_info_by_topic(topic)
        except (RuntimeError, ValueError):
            return []
        return [qos_from_rclpy(info.qos_profile) for info in infos
                if info.node_name != self.get_name()]

    def _flush(self) -> None:
        """Put the messages written so far on disk (a timer: also when nothing arrives)."""
        if self._writer is not None:
            self._writer.flush_if_due(FLUSH_PERIOD_S, COMMIT_EVERY)

    @property
    def recorded_subscriptions(self) -> list[Subscription]:
        """The (raw) subscriptions of the recorded topics, one per topic."""
        return list(self._subscriptions_by_topic.values())

    def status(self) -> DiagnosticStatus:
        """Health of the recording: per topic, messages written and publishers matched."""
        values = []
        for name, subscription in self._subscriptions_by_topic.items():
            values.append(KeyValue(key=f'{name} messages', value=str(self.counts[name])))
            values.append(
                KeyValue(key=f'{name} publishers', value=str(subscription.get_publisher_count()))
            )
            if name in self.duplicates:
                values.append(KeyValue(key=f'{name} duplicates', value=str(self.duplicates[name])))
        recording = self._writer is not None
        if recording:
            values.append(KeyValue(key='flushed messages', value=str(self._writer.flushed)))
        level = DiagnosticStatus.OK if recording else DiagnosticStatus.WARN
        state = 'recording' if recording else 'closed'
        return DiagnosticStatus(
            level=level,
            name=f'{self.get_name()}: bag',
            message=f'{state} {self.total} messages into {self.bag_path}',
            hardware_id=str(self.bag_path),
            values=values,
        )

    def _publish_status(self) -> None:
        """Publish :meth:`status` on ``/diagnostics`` (every second of wall time)."""
        array = DiagnosticArray(status=[self.status()])
        array.header.stamp = self.get_clock().now().to_msg()
        self._status_publisher.publish(array)

    @property
    def total(self) -> int:
        """Messages written so far, all topics."""
        return sum(self.counts.values())

    def close_bag(self) -> None:
        """Close the bag (writes metadata.yaml) and log the message counts; idempotent."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        writer.close()
        summary = ', '.join(f'{name}: {n}' for name, n in self.counts.items() if n)
        self.get_logger().info(
            f'closed {self.bag_path}: {self.total} messages ({summary or "none"})'
        )


SAMPLE_LOOKAHEAD = 10_000_000
"""A sample index this far beyond the highest seen (10 000 s) is not a loop sample."""


def _seen_before(seen: bytearray, sample: int) -> bool | None:
    """Mark ``sample`` in the bit set ``seen``; True if it was marked already.

    None (not marked) for an index so far ahead that it cannot be the loop's: such a
    message is recorded as it is, stamped with the clock.
    """
    byte, bit = divmod(sample, 8)
    if byte >= len(seen) + SAMPLE_LOOKAHEAD // 8:
        return None
    if byte >= len(seen):
        seen.extend(bytes(byte + 1 - len(seen) + 4096))
    if seen[byte] >> bit & 1:
        return True
    seen[byte] |= 1 << bit
    return False


def _open_writer(path: Path, plugin: StoragePlugin, custom_data: dict[str, str]) -> JazzyWriter:
    """Create and open the bag, refusing to overwrite anything."""
    if path.exists():
        raise RecorderError(
            f'bag directory {path} exists already; refusing to overwrite it '
            '(remove it or choose another bag_path)'
        )
    writer = JazzyWriter(path, storage_plugin=plugin)
    for key, value in custom_data.items():
        writer.set_custom_data(key, value)
    try:
        writer.open()
    except (WriterError, OSError) as err:
        raise RecorderError(f'cannot create bag {path}: {err}') from err
    return writer


def _drain(spinner: LoopSpinner, recorder: BagRecorder) -> None:
    """Write the messages already queued: spin until idle, at most DRAIN_MAX_S."""
    deadline = time.monotonic() + DRAIN_MAX_S
    idle = 0
    while idle < DRAIN_IDLE_SPINS and time.monotonic() < deadline:
        before = recorder.total
        spinner.spin_once(DRAIN_SPIN_S)
        idle = idle + 1 if recorder.total == before else 0


def _install_stop_handlers() -> threading.Event:
    """An event set by SIGINT or SIGTERM (instead of rclpy's immediate shutdown)."""
    stop = threading.Event()

    def handler(signum: int, frame: object) -> None:
        stop.signum = getattr(stop, 'signum', signum)   # the first one: the exit code
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def run(args: list[str] | None = None) -> int:
    """Record until SIGINT/SIGTERM; return the process exit code."""
    stop = _install_stop_handlers()
    if cli.stop_requested() is not None:     # it came during the imports
        return cli.interrupted_exit_code()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        try:
            recorder = BagRecorder()
        except (RecorderError, ValueError) as err:
            print(f'{NODE_NAME}: error: {err}', file=sys.stderr)
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(recorder)
        # The recorded topics are waited on in one persistent wait set and taken directly
        # (ros/executors.py); the executor serves the rest (timers, parameter services)
        # every SERVICE_PERIOD_S. rclpy's executor rebuilt its wait set and went through a
        # task for every wake-up: 85 % of the recorder's CPU in a lockstep run (py-spy).
        spinner = LoopSpinner(executor, recorder.recorded_subscriptions, fast=True)
        try:
            while not stop.is_set():
                spinner.spin_once(0.1)
            _drain(spinner, recorder)
        finally:
            recorder.close_bag()
            executor.remove_node(recorder)
            recorder.destroy_node()
    finally:
        rclpy.try_shutdown()
    return 128 + stop.signum if stop.is_set() else 0


def main(args: list[str] | None = None) -> None:
    """Entry point of ``pph_recorder``: exit 0, 2 (bad parameter), 130/143 (SIGINT/SIGTERM)."""
    args = cli.node_command_line(NODE_NAME, (NODE_NAME,), args)
    cli.exit_now(run(args))


if __name__ == "__main__":
    main()
