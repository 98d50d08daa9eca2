"""The driver's reports (held commands, stand-ins): what they carry, what the notch takes.

In-process nodes on the test's domain: a publisher of reports as ``DriverReports`` makes
them (``make_vector_array`` with the rows label) and a node subscribed with
``subscribe_held_reports``. A bad report is refused and changes nothing; a report of
another run is dropped.
"""

from __future__ import annotations

import pytest
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    HELD_ROWS_LABEL,
    NOTCH_HELD_TOPIC,
    STAND_IN_ROWS_LABEL,
    InvalidStrutMessage,
)
from hexapod_vibration.ros.held_reports import (
    parse_held_report,
    parse_stand_in_report,
    subscribe_held_reports,
)
from hexapod_vibration.ros.messages import make_vector_array
from hexapod_vibration.ros.qos import HELD_QOS

HANG_GUARD_S = 30.0
RUN = 77


def _report(rows, covered, run=RUN, label=HELD_ROWS_LABEL) -> Float64MultiArray:
    return make_vector_array([float(v) for row in rows for v in row], covered, run, label=label)


def test_a_report_reads_back_as_it_was_written():
    rows = [(3, 4, 2, 1.0), (11, 11, 6, 0.25), (12, 12, 6, 0.0), (13, 14, -1, 0.0)]
    assert parse_held_report(_report(rows, 99)) == (rows, 99, RUN)
    assert parse_held_report(_report([], 199)) == ([], 199, RUN)


@pytest.mark.parametrize("message", [
    _report([(3, 4, 2, 1.0)], 99, label="frequency_hz"),             # another topic's array
    make_vector_array([3.0, 4.0, 2.0], 99, RUN, label=HELD_ROWS_LABEL),    # not whole rows
    make_vector_array([3.0, 4.5, 2.0, 1.0], 99, RUN, label=HELD_ROWS_LABEL),   # not integers
    make_vector_array([5.0, 4.0, 2.0, 1.0], 99, RUN, label=HELD_ROWS_LABEL),   # last < first
    make_vector_array([3.0, 4.0, -7.0, 1.0], 99, RUN, label=HELD_ROWS_LABEL),  # applied < -1
    make_vector_array([3.0, 4.0, 2.0, 1.5], 99, RUN, label=HELD_ROWS_LABEL),   # gain > 1
    make_vector_array([3.0, 4.0, 2.0, -0.1], 99, RUN, label=HELD_ROWS_LABEL),  # gain < 0
    make_vector_array([3.0, 4.0, 2.0, 1.0], None, label=HELD_ROWS_LABEL),      # no coverage
])
def test_a_bad_report_is_refused(message):
    with pytest.raises(InvalidStrutMessage):
        parse_held_report(message)


def test_the_subscriber_takes_good_reports_of_its_run_only(ros_context):
    driver = ros_context.create_node("held_driver")
    notch = ros_context.create_node("held_notch")
    got: list[tuple[list, int]] = []
    subscribe_held_reports(notch, lambda: RUN, lambda rows, covered: got.append((rows, covered)))
    publisher = driver.create_publisher(Float64MultiArray, NOTCH_HELD_TOPIC, HELD_QOS)
    assert ros_context.wait_for(lambda: publisher.get_subscription_count() > 0, HANG_GUARD_S)
    publisher.publish(_report([(3, 4, 2, 1.0)], 99, run=RUN + 1))     # a restarted driver's
    publisher.publish(_report([(3, 4, 2)], 99))                        # refused
    publisher.publish(_report([(5, 6, -1, 0.0)], 199))
    assert ros_context.wait_for(lambda: got, HANG_GUARD_S)
    assert got == [([(5, 6, -1, 0.0)], 199)]


def test_a_stand_in_report_reads_back_and_a_bad_one_is_refused():
    rows = [(3, 4, 0), (11, 11, 1)]
    assert parse_stand_in_report(_report(rows, 99, label=STAND_IN_ROWS_LABEL)) == (
        rows, 99, RUN)
    for bad in (_report([(3, 4, 2, 1.0)], 99),                             # a held report
                make_vector_array([4.0, 3.0, 0.0], 99, RUN, label=STAND_IN_ROWS_LABEL),
                make_vector_array([-1.0, 3.0, 0.0], 99, RUN, label=STAND_IN_ROWS_LABEL),
                make_vector_array([3.0, 4.0, 0.5], 99, RUN, label=STAND_IN_ROWS_LABEL),
                make_vector_array([3.0, 4.0], 99, RUN, label=STAND_IN_ROWS_LABEL)):
        with pytest.raises(InvalidStrutMessage):
            parse_stand_in_report(bad)
