"""pph_recorder as a real process: what an in-test node publishes comes back from the bag."""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.analysis.bag_io import read_clock, read_strut_topics
from hexapod_vibration.ros.messages import make_strut_array
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS

TIMEOUT_S = 60.0  # hang guard only: nothing here asserts how long anything takes
SKIPPED_SAMPLE = 57
SIM_TIME_NS = 100_000_000_000
# Deep enough that a sample sent before the recorder's reader matched is still in the
# publisher's history when DDS repairs it (the loop's own LOOP_QOS keeps only 10).
PUBLISHER_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


class RecorderStatus:
    """Latest status the recorder published on /diagnostics."""

    def __init__(self):
        self.values: dict[str, str] = {}

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith('pph_recorder'):
                self.values = {kv.key: kv.value for kv in status.values}

    def count(self, key: str) -> int:
        return int(self.values.get(key, '0'))


def _clock_message(time_ns: int) -> Clock:
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(time_ns, 1_000_000_000)
    return msg


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_recorder_writes_published_samples(ros_context, node_processes, tmp_path, storage):
    bag = tmp_path / 'bag'
    recorder = node_processes.start(
        'pph_recorder', '--ros-args', '-p', f'bag_path:={bag}', '-p', f'storage:={storage}'
    )
    node = ros_context.create_node('test_publisher')
    accel = node.create_publisher(Float64MultiArray, '/pph/accel', PUBLISHER_QOS)
    clock = node.create_publisher(Clock, '/clock', PUBLISHER_QOS)
    status = RecorderStatus()
    node.create_subscription(
        DiagnosticArray, '/diagnostics', status.on_diagnostics, DIAGNOSTICS_QOS
    )

    # Handshake: the recorder itself reports our publisher matched and sim time received.
    ready = ros_context.wait_for(
        lambda: status.count('/pph/accel publishers') >= 1 and status.count('/clock messages') >= 3,
        TIMEOUT_S,
        step=lambda: clock.publish(_clock_message(SIM_TIME_NS)),
    )
    assert ready, recorder.output()

    indices = np.array([n for n in range(200) if n != SKIPPED_SAMPLE])
    values = np.random.default_rng(7).normal(0.0, 9.81, size=(indices.size, 6))
    for n, row in zip(indices, values, strict=True):
        accel.publish(make_strut_array(row, int(n)))
    done = ros_context.wait_for(
        lambda: status.count('/pph/accel messages') >= indices.size, TIMEOUT_S
    )
    assert done, recorder.output()

    assert recorder.stop() == 130, recorder.output()   # SIGINT: 128 + 2 (issue 15)
    assert (bag / 'metadata.yaml').is_file()
    assert 'closed' in recorder.output()
    series = read_strut_topics(bag)['/pph/accel']
    assert len(series) == 199
    assert series.missing_samples == 1
    assert series.duplicate_samples == 0
    assert series.index_source == 'in-band'
    np.testing.assert_array_equal(series.sample_index, indices)
    np.testing.assert_array_equal(series.values, values)
    # use_sim_time defaults to true: messages are stamped with the /clock time.
    assert set(series.timestamp_ns.tolist()) == {SIM_TIME_NS}
    stamps, clock_ns = read_clock(bag)
    assert clock_ns.size >= 3 and set(clock_ns.tolist()) == {SIM_TIME_NS}


def test_recorder_writes_queued_messages_at_sigint(ros_context, node_processes, tmp_path):
    """Acknowledged messages are in the bag even if SIGINT comes before they were written."""
    bag = tmp_path / 'bag'
    recorder = node_processes.start('pph_recorder', '--ros-args', '-p', f'bag_path:={bag}')
    node = ros_context.create_node('test_publisher')
    accel = node.create_publisher(Float64MultiArray, '/pph/accel', PUBLISHER_QOS)
    status = RecorderStatus()
    node.create_subscription(
        DiagnosticArray, '/diagnostics', status.on_diagnostics, DIAGNOSTICS_QOS
    )
    ready = ros_context.wait_for(lambda: status.count('/pph/accel publishers') >= 1, TIMEOUT_S)
    assert ready, recorder.output()

    values = np.random.default_rng(8).normal(size=(1000, 6))
    for n, row in enumerate(values):
        accel.publish(make_strut_array(row, n))
    assert accel.wait_for_all_acked(Duration(seconds=TIMEOUT_S)), recorder.output()
    assert recorder.stop() == 130, recorder.output()   # SIGINT: 128 + 2 (issue 15)
    series = read_strut_topics(bag)['/pph/accel']
    assert series.missing_samples == 0
    np.testing.assert_array_equal(series.sample_index, np.arange(1000))
    np.testing.assert_array_equal(series.values, values)


def test_recorder_refuses_to_overwrite(node_processes, tmp_path):
    bag = tmp_path / 'existing'
    bag.mkdir()
    (bag / 'keep.txt').write_text('precious')
    recorder = node_processes.start('pph_recorder', '--ros-args', '-p', f'bag_path:={bag}')
    code = recorder.wait(TIMEOUT_S)
    assert code == 2, recorder.output()
    assert 'exists already' in recorder.output()
    assert (bag / 'keep.txt').read_text() == 'precious'
    assert sorted(p.name for p in bag.iterdir()) == ['keep.txt']


def test_recorder_rejects_unknown_storage(node_processes, tmp_path):
    bag = tmp_path / 'bag'
    recorder = node_processes.start(
        'pph_recorder', '--ros-args', '-p', f'bag_path:={bag}', '-p', 'storage:=rosbag1'
    )
    assert recorder.wait(TIMEOUT_S) == 2, recorder.output()
    assert 'rosbag1' in recorder.output() and 'mcap' in recorder.output()
    assert not bag.exists()
