"""A realtime driver reports the notch commands it held and the samples a controller skipped.

``/pph/notch_held`` and ``/pph/stand_ins``.

With no notch controller on the graph every due sample gets zero force, so, whatever the
machine's timing, the reports' rows must tile every due sample from 0 to the last one
covered, each with ``applied = -1``, the coverage growing report by report (one every 100
samples). The reports are best effort, each repeating the rows of the 9 before it: a
reader takes the rows it has not had (``FreshRows``, as the notch controller does), and the
tiling holds even if a report is lost on a loaded machine.
"""

from __future__ import annotations

import numpy as np
from node_graph import RecorderStatus, wait_until
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import HELD_REPORT_EVERY_SAMPLES, NOTCH_HELD_TOPIC, STAND_INS_TOPIC
from hexapod_vibration.core.loop.repeated_reports import FreshRows
from hexapod_vibration.nodes.driver_loop import REFRESH_EVERY_SAMPLES
from hexapod_vibration.ros.held_reports import parse_held_report, parse_stand_in_report
from hexapod_vibration.ros.messages import make_strut_array, parse_strut_sample
from hexapod_vibration.ros.qos import COMMAND_QOS, HELD_QOS, LOOP_QOS

REPORTS = 5


def _fresh(reports: list) -> list:
    """Every row of ``reports`` ((rows, covered, run), in order) once, as a reader takes them."""
    fresh, rows = FreshRows(), []
    for report_rows, covered, run in reports:
        rows += fresh.take(report_rows, covered, run) or []
    return rows


def _tiles_with_zero_force(rows: list, last: int) -> bool:
    """``rows`` are runs of zero force ``(first, last, -1, 0.0)`` tiling their span to ``last``."""
    return (all(row[2:] == (-1, 0.0) for row in rows) and rows[-1][1] == last
            and all(b[0] == a[1] + 1 for a, b in zip(rows, rows[1:], strict=False)))


def _listen(ros_context) -> list:
    reports: list = []
    node = ros_context.create_node("held_listener")
    node.create_subscription(Float64MultiArray, NOTCH_HELD_TOPIC,
                             lambda msg: reports.append(parse_held_report(msg)), HELD_QOS)
    return reports


def test_a_realtime_driver_without_a_notch_reports_every_sample_at_zero_force(
        ros_context, node_processes):
    reports = _listen(ros_context)
    node_processes.start("pph_driver", "--ros-args", "-p", "clock_mode:=realtime",
                         "-p", "lockstep_controllers:=[]", "-p", "command_delay_samples:=1")
    assert wait_until(ros_context, lambda: len(reports) >= REPORTS)
    covered = [c for _, c, _ in reports]
    assert all((b - a) % HELD_REPORT_EVERY_SAMPLES == 0 and b > a
               for a, b in zip(covered, covered[1:], strict=False)), covered
    assert {run for _, _, run in reports} == {reports[0][2]}
    # Each report: one run of zero force per report it repeats, the newest ending at its
    # coverage; all of them, once each: every due sample from the first report's.
    assert all(rows[-1][1] == c and len(rows) <= 10 for rows, c, _ in reports), reports
    rows = _fresh(reports)
    assert _tiles_with_zero_force(rows, covered[-1]), rows


SKIP_EVERY = 50
"""The test's pointing 'controller' never answers samples n with n % SKIP_EVERY == 7."""


def test_a_realtime_driver_reports_every_sample_a_controller_skipped_as_a_stand_in(
        ros_context, node_processes):
    """``/pph/stand_ins``: every sample a controller skipped is reported.

    A pointing stream answered with one constant command except at skipped samples: a late
    answer equals the held command (cleared: the stand-in was right); a skipped sample never
    gets one, so whatever the timing it must be reported (the watchdog's timeout is long
    enough that the stream never goes stale).
    """
    node = ros_context.create_node("stand_in_controller")
    reports: list = []
    node.create_subscription(Float64MultiArray, STAND_INS_TOPIC,
                             lambda msg: reports.append(parse_stand_in_report(msg)), HELD_QOS)
    commands = node.create_publisher(Float64MultiArray, "/pph/pointing_command", COMMAND_QOS)
    answered: list[int] = []

    def answer(msg: Float64MultiArray) -> None:
        sample = parse_strut_sample(msg)
        if sample.index % SKIP_EVERY != 7:
            commands.publish(make_strut_array(np.full(6, 0.5), sample.index, sample.run))
            answered.append(sample.index)

    node.create_subscription(Float64MultiArray, "/pph/accel", answer, LOOP_QOS)
    node_processes.start("pph_driver", "--ros-args", "-p", "clock_mode:=realtime",
                         "-p", "lockstep_controllers:=[]", "-p", "command_timeout_samples:=1000")
    assert wait_until(ros_context, lambda: len(reports) >= REPORTS and answered
                      and reports[-1][1] > answered[0] + REFRESH_EVERY_SAMPLES + 3 * SKIP_EVERY)
    rows = _fresh(reports)
    reported = {n for first, last, _ in rows for n in range(first, last + 1)}
    covered = reports[-1][1]
    # The driver counts a stream from its first accepted command, or its next look at the
    # graph (every REFRESH_EVERY_SAMPLES samples) if that comes first; when the first
    # command arrived depends on the machine, so only the bound the graph gives is checked
    # (the first-command rule is exact in test/core/test_command_arbiter.py).
    seen = (answered[0] // REFRESH_EVERY_SAMPLES + 1) * REFRESH_EVERY_SAMPLES
    skipped = [n for n in range(seen + 1, covered + 1) if n % SKIP_EVERY == 7]
    assert skipped and set(skipped) <= reported, (skipped, rows)
    assert all(a[1] < b[0] for a, b in zip(rows, rows[1:], strict=False)), rows   # in order


def _recorded(bag, topic: str, parse) -> list:
    """The messages of ``topic`` in an MCAP bag, decoded by the independent mcap reader."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with (bag / "bag_0.mcap").open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [parse(msg) for _, _, _, msg in reader.iter_decoded_messages(topics=[topic])]


def test_the_recorder_records_the_reports_a_listener_gets(ros_context, node_processes,
                                                           tmp_path):
    """``pph_recorder`` records ``/pph/notch_held`` and ``/pph/stand_ins``.

    Read back by the independent mcap reader (what rosbag2 reads) and by rosbags, every
    held report in the bag is the one a listener got for the same coverage, and their rows
    tile every due sample from the first recorded to the last; the stand-in reports are
    there (empty: no controller).
    """
    reports = _listen(ros_context)
    recorder_status = RecorderStatus(ros_context.create_node("recorder_status"))
    bag = tmp_path / "bag"
    recorder = node_processes.start("pph_recorder", "--ros-args", "-p", f"bag_path:={bag}")
    driver = node_processes.start("pph_driver", "--ros-args", "-p", "clock_mode:=realtime",
                                  "-p", "lockstep_controllers:=[]",
                                  "-p", "command_delay_samples:=1")

    # The recorder may match the driver's reports seconds after a listener does (its
    # imports): wait for what it says it wrote, not for what the listener heard.
    assert wait_until(ros_context, lambda:
                      recorder_status.count(f"{NOTCH_HELD_TOPIC} messages") >= REPORTS
                      and recorder_status.count(f"{STAND_INS_TOPIC} messages") >= 1
                      and len(reports) >= REPORTS)
    assert driver.stop() == 130, driver.output()
    assert recorder.stop() == 130, recorder.output()
    held = _recorded(bag, NOTCH_HELD_TOPIC, parse_held_report)
    heard = {covered: rows for rows, covered, _ in reports}
    assert held, recorder.output()
    covered = [c for _, c, _ in held]
    assert all((b - a) % HELD_REPORT_EVERY_SAMPLES == 0 and b > a
               for a, b in zip(covered, covered[1:], strict=False)), covered
    assert _tiles_with_zero_force(_fresh(held), covered[-1]), held
    assert all(rows == heard[c] for rows, c, _ in held if c in heard), (held, reports)
    assert set(covered) & set(heard)
    stand_ins = _recorded(bag, STAND_INS_TOPIC, parse_stand_in_report)
    assert stand_ins and all(rows == [] for rows, _, _ in stand_ins), stand_ins
    # rosbags (the bag library users read with) deserializes every report too: it refused
    # an empty one with Fast CDR's padding after the data's length ("CDR message size
    # mismatch"); the driver now writes the CDR standard's empty sequence.
    assert _deserialized_by_rosbags(bag, (NOTCH_HELD_TOPIC, STAND_INS_TOPIC)) == {
        NOTCH_HELD_TOPIC: len(held), STAND_INS_TOPIC: len(stand_ins)}


def _deserialized_by_rosbags(bag, topics) -> dict[str, int]:
    """How many messages of each of ``topics`` rosbags' AnyReader deserializes (it raises)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    counts = dict.fromkeys(topics, 0)
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        chosen = [c for c in reader.connections if c.topic in counts]
        for connection, _, raw in reader.messages(connections=chosen):
            reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] += 1
    return counts
