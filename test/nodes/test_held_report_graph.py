"""A realtime driver reports every notch command it held, on ``/pph/notch_held``.

With no notch controller on the graph every due sample gets zero force, so, whatever the
machine's timing, the reports' rows must tile every due sample from 0 to the last one
covered, each with ``applied = -1``, the coverage growing report by report (one every 100
samples).
"""

from __future__ import annotations

from node_graph import wait_until
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import HELD_REPORT_EVERY_SAMPLES, NOTCH_HELD_TOPIC
from hexapod_vibration.ros.held_reports import parse_held_report
from hexapod_vibration.ros.qos import HELD_QOS

REPORTS = 5


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
    assert all(b - a == HELD_REPORT_EVERY_SAMPLES for a, b in zip(covered, covered[1:],
                                                                  strict=False)), covered
    assert {run for _, _, run in reports} == {reports[0][2]}
    # One run of zero force per report: the due samples since the report before.
    assert [rows for rows, _, _ in reports] == [
        [(c - HELD_REPORT_EVERY_SAMPLES + 1, c, -1)] for c in covered]
