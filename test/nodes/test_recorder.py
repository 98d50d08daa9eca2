"""pph_recorder as a real process: what an in-test node publishes comes back from the bag."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from node_graph import RecorderStatus
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.analysis.bag_reading import read_clock, read_strut_topics
from hexapod_vibration.ros.messages import make_strut_array

TIMEOUT_S = 60.0  # hang guard only: nothing here asserts how long anything takes
SKIPPED_SAMPLE = 57
SIM_TIME_NS = 100_000_000_000
# Deep enough that a sample sent before the recorder's reader matched is still in the
# publisher's history when DDS repairs it (the loop's own LOOP_QOS keeps only 10).
PUBLISHER_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def _clock_message(time_ns: int) -> Clock:
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(time_ns, 1_000_000_000)
    return msg


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_recorder_writes_published_samples(ros_context, node_processes, tmp_path, storage):
    bag = tmp_path / "bag"
    recorder = node_processes.start(
        "pph_recorder", "--ros-args", "-p", f"bag_path:={bag}", "-p", f"storage:={storage}"
    )
    node = ros_context.create_node("test_publisher")
    accel = node.create_publisher(Float64MultiArray, "/pph/accel", PUBLISHER_QOS)
    clock = node.create_publisher(Clock, "/clock", PUBLISHER_QOS)
    status = RecorderStatus(node)

    # Handshake: the recorder itself reports our publisher matched and sim time received.
    ready = ros_context.wait_for(
        lambda: status.count("/pph/accel publishers") >= 1 and status.count("/clock messages") >= 3,
        TIMEOUT_S,
        step=lambda: clock.publish(_clock_message(SIM_TIME_NS)),
    )
    assert ready, recorder.output()

    indices = np.array([n for n in range(200) if n != SKIPPED_SAMPLE])
    values = np.random.default_rng(7).normal(0.0, 9.81, size=(indices.size, 6))
    eddy_pub = node.create_publisher(Float64MultiArray, "/pph/eddy", PUBLISHER_QOS)
    for n, row in zip(indices, values, strict=True):
        accel.publish(make_strut_array(row, int(n)))
    eddy_pub.publish(make_strut_array(values[0], None))
    done = ros_context.wait_for(
        lambda: status.count("/pph/accel messages") >= indices.size
        and status.count("/pph/eddy messages") >= 1, TIMEOUT_S
    )
    assert done, recorder.output()

    assert recorder.stop() == 130, recorder.output()   # SIGINT: 128 + 2
    assert (bag / "metadata.yaml").is_file()
    assert "closed" in recorder.output()
    series = read_strut_topics(bag)["/pph/accel"]
    assert len(series) == 199
    assert series.missing_samples == 1
    assert series.duplicate_samples == 0
    assert series.index_source == "in-band"
    np.testing.assert_array_equal(series.sample_index, indices)
    np.testing.assert_array_equal(series.values, values)
    # Loop messages are stamped with their sample's sim time (sample n: n ms) ...
    np.testing.assert_array_equal(series.timestamp_ns, indices * 1_000_000)
    # ... /clock with the time it carries, and (use_sim_time defaults to true) a message
    # without a sample index with the /clock time.
    stamps, clock_ns = read_clock(bag)
    assert clock_ns.size >= 3 and set(clock_ns.tolist()) == {SIM_TIME_NS}
    assert set(stamps.tolist()) == {SIM_TIME_NS}
    eddy = read_strut_topics(bag, topics=("/pph/eddy",))["/pph/eddy"]
    assert eddy.index_source == "timestamp" and len(eddy) == 1


def test_recorder_writes_queued_messages_at_sigint(ros_context, node_processes, tmp_path):
    """Acknowledged messages are in the bag even if SIGINT comes before they were written."""
    bag = tmp_path / "bag"
    recorder = node_processes.start("pph_recorder", "--ros-args", "-p", f"bag_path:={bag}")
    node = ros_context.create_node("test_publisher")
    accel = node.create_publisher(Float64MultiArray, "/pph/accel", PUBLISHER_QOS)
    status = RecorderStatus(node)
    ready = ros_context.wait_for(lambda: status.count("/pph/accel publishers") >= 1, TIMEOUT_S)
    assert ready, recorder.output()

    values = np.random.default_rng(8).normal(size=(1000, 6))
    for n, row in enumerate(values):
        accel.publish(make_strut_array(row, n))
    assert accel.wait_for_all_acked(Duration(seconds=TIMEOUT_S)), recorder.output()
    assert recorder.stop() == 130, recorder.output()   # SIGINT: 128 + 2
    series = read_strut_topics(bag)["/pph/accel"]
    assert series.missing_samples == 0
    np.testing.assert_array_equal(series.sample_index, np.arange(1000))
    np.testing.assert_array_equal(series.values, values)


def test_recorder_refuses_to_overwrite(node_processes, tmp_path):
    bag = tmp_path / "existing"
    bag.mkdir()
    (bag / "keep.txt").write_text("precious")
    recorder = node_processes.start("pph_recorder", "--ros-args", "-p", f"bag_path:={bag}")
    code = recorder.wait(TIMEOUT_S)
    assert code == 2, recorder.output()
    assert "exists already" in recorder.output()
    assert (bag / "keep.txt").read_text() == "precious"
    assert sorted(p.name for p in bag.iterdir()) == ["keep.txt"]


def test_recorder_rejects_unknown_storage(node_processes, tmp_path):
    bag = tmp_path / "bag"
    recorder = node_processes.start(
        "pph_recorder", "--ros-args", "-p", f"bag_path:={bag}", "-p", "storage:=rosbag1"
    )
    assert recorder.wait(TIMEOUT_S) == 2, recorder.output()
    assert "rosbag1" in recorder.output() and "mcap" in recorder.output()
    assert not bag.exists()


def _record(ros_context, node_processes, bag, storage, publish, wait_key, wait_count,
            run_record=""):
    """Start the recorder, publish once it matched, wait for its own count ``wait_key``."""
    args = ["--ros-args", "-p", f"bag_path:={bag}", "-p", f"storage:={storage}"]
    if run_record:   # as the experiment runner passes it: a params file (JSON is not YAML)
        params = bag.parent / "recorder.yaml"
        params.write_text(yaml.safe_dump(
            {"pph_recorder": {"ros__parameters": {"run_record": run_record}}}))
        args += ["--params-file", str(params)]
    recorder = node_processes.start("pph_recorder", *args)
    node = ros_context.create_node("test_publisher")
    publishers = {t: node.create_publisher(Float64MultiArray, t, PUBLISHER_QOS)
                  for t in ("/pph/accel", "/pph/notch_command")}
    status = RecorderStatus(node)
    ready = ros_context.wait_for(
        lambda: all(status.count(f"{t} publishers") >= 1 for t in publishers), TIMEOUT_S)
    assert ready, recorder.output()
    publish(publishers)
    done = ros_context.wait_for(lambda: status.count(wait_key) >= wait_count, TIMEOUT_S)
    assert done, (status.values, recorder.output())
    return recorder, status


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_recorder_drops_repeated_samples_and_writes_jazzy_metadata(
        ros_context, node_processes, tmp_path, storage):
    """One message per sample; rosbag2 Jazzy's names, ros_distro and offered QoS.

    The lockstep handshake re-offers sample 0; the metadata round-trips through rosbags.
    """
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.rosbag2 import Reader

    bag = tmp_path / "bag"
    values = np.random.default_rng(3).normal(size=(300, 6))

    def publish(pubs):
        for _ in range(5):                         # sample 0 offered five times
            pubs["/pph/accel"].publish(make_strut_array(values[0], 0))
        for n in range(1, 300):
            pubs["/pph/accel"].publish(make_strut_array(values[n], n))
            pubs["/pph/notch_command"].publish(make_strut_array(values[n], n))

    recorder, status = _record(ros_context, node_processes, bag, storage, publish,
                               "/pph/notch_command messages", 299)
    ros_context.wait_for(lambda: status.count("/pph/accel duplicates") >= 4
                         and status.count("/pph/accel messages") >= 300, TIMEOUT_S)
    assert status.count("/pph/accel duplicates") == 4
    assert recorder.stop() == 130, recorder.output()     # SIGINT: 128 + 2
    suffix = {"mcap": "mcap", "sqlite3": "db3"}[storage]
    assert sorted(p.name for p in bag.iterdir()) == [f"bag_0.{suffix}", "metadata.yaml"]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["ros_distro"] == "jazzy" and meta["version"] == 9
    assert meta["relative_file_paths"] == [f"bag_0.{suffix}"]
    assert "hexapod_vibration.recording" not in (meta.get("custom_data") or {})
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    offered = topics["/pph/accel"]["topic_metadata"]["offered_qos_profiles"]
    assert isinstance(offered, list) and len(offered) == 1
    assert offered[0]["reliability"] == "reliable" and offered[0]["durability"] == "volatile"
    assert topics["/pph/accel"]["message_count"] == 300
    with Reader(bag) as reader:
        assert reader.ros_distro == "jazzy"
        (conn,) = [c for c in reader.connections if c.topic == "/pph/accel"]
        (qos,) = conn.ext.offered_qos_profiles
        assert qos.reliability == QosReliability.RELIABLE
        assert qos.durability == QosDurability.VOLATILE
    series = read_strut_topics(bag)["/pph/accel"]
    assert series.duplicate_samples == 0 and len(series) == 300
    np.testing.assert_array_equal(series.values, values)


def test_an_independent_mcap_reader_decodes_every_recorded_message(
        ros_context, node_processes, tmp_path):
    """The mcap and mcap-ros2-support packages read and decode the whole recorded bag."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag = tmp_path / "bag"
    values = np.random.default_rng(5).normal(size=(500, 6))

    def publish(pubs):
        for n in range(500):
            pubs["/pph/accel"].publish(make_strut_array(values[n], n))

    recorder, _ = _record(ros_context, node_processes, bag, "mcap", publish,
                          "/pph/accel messages", 500, run_record='{"scenario": "x"}')
    assert recorder.stop() == 130, recorder.output()     # SIGINT: 128 + 2
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in meta["topics_with_message_count"]}
    assert meta["custom_data"] == {"hexapod_vibration.run": '{"scenario": "x"}'}
    decoded = {}
    with (bag / "bag_0.mcap").open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for _schema, channel, message, ros_msg in reader.iter_decoded_messages():
            decoded[channel.topic] = decoded.get(channel.topic, 0) + 1
            if channel.topic == "/pph/accel":
                n = int(ros_msg.layout.dim[1].label.split(":")[1])
                assert message.log_time == n * 1_000_000
                np.testing.assert_array_equal(np.asarray(ros_msg.data), values[n])
    assert decoded == counts
    assert decoded["/pph/accel"] == 500


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_killed_recorder_leaves_a_bag_the_analysis_reads(
        ros_context, node_processes, tmp_path, storage):
    """SIGKILL: every message flushed before the kill is read back, with the run record."""
    import signal as signals

    from hexapod_vibration.analysis.bag_reading import read_bag

    bag = tmp_path / "bag"
    values = np.random.default_rng(6).normal(size=(1000, 6))   # within the publisher's depth

    def publish(pubs):
        for n in range(1000):
            pubs["/pph/accel"].publish(make_strut_array(values[n], n))

    recorder, status = _record(ros_context, node_processes, bag, storage, publish,
                               "flushed messages", 1000, run_record='{"scenario": "k"}')
    recorder.process.send_signal(signals.SIGKILL)
    assert recorder.wait(TIMEOUT_S) == -signals.SIGKILL
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"]["hexapod_vibration.recording"] == "open"   # never closed
    content = read_bag(bag)
    assert "not closed" in content.recovered
    assert content.custom_data["hexapod_vibration.run"] == '{"scenario": "k"}'
    series = content.strut["/pph/accel"]
    assert len(series) == 1000 and series.missing_samples == 0
    np.testing.assert_array_equal(series.values, values)
