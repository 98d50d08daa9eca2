"""The notch controller's end of the driver's reports: held commands and stand-ins.

A realtime driver reports, every 100 samples, the runs of due samples whose notch command it
did not apply (``contract.NOTCH_HELD_TOPIC``) and those where a stand-in no controller
computed went in (``contract.STAND_INS_TOPIC``). :func:`subscribe_held_reports` and
:func:`subscribe_stand_in_reports` check each report (its bytes, its label, whole rows, its
run) and hand the rows to the controller; a bad one is refused with a throttled warning and
changes nothing. The subscription is one of
the node's loop subscriptions (raw, served at every wake-up of the ``waitset`` spinner):
the executor's service of the other callbacks, one callback per 50 ms that loop messages
compete for, fell behind the 10 Hz reports.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from rclpy.node import Node
from rclpy.subscription import Subscription
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    HELD_ROWS_LABEL,
    NOTCH_HELD_TOPIC,
    STAND_IN_ROWS_LABEL,
    STAND_INS_TOPIC,
    InvalidStrutMessage,
)
from hexapod_vibration.ros.messages import create_parsed_subscription, parse_labelled_sample
from hexapod_vibration.ros.qos import HELD_QOS

Rows = list[tuple[int, ...]]


def _parse_rows(msg: Float64MultiArray, label: str, columns: int
                ) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a report of rows ``(first due, last due, ...)``.

    Raises:
        InvalidStrutMessage: another label, not whole rows of integers (>= -1), a row
            whose due samples are not ``0 <= first <= last``, no sample label.
    """
    sample = parse_labelled_sample(msg, label, columns)
    values = sample.values
    if np.any(values != np.round(values)) or np.any(values < -1):
        raise InvalidStrutMessage(f"expected rows of {columns} sample indices, got "
                                  f"{values.size} values")
    rows = [tuple(int(v) for v in row) for row in values.reshape(-1, columns)]
    if any(row[0] < 0 or row[1] < row[0] for row in rows):
        raise InvalidStrutMessage("a row's due samples are not first <= last, both >= 0")
    return rows, sample.index, sample.run


def parse_held_report(msg: Float64MultiArray) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a ``/pph/notch_held`` message (rows of 3)."""
    return _parse_rows(msg, HELD_ROWS_LABEL, 3)


def parse_stand_in_report(msg: Float64MultiArray) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a ``/pph/stand_ins`` message (rows of 2)."""
    return _parse_rows(msg, STAND_IN_ROWS_LABEL, 2)


def _subscribe(node: Node, topic: str, parse: Callable, current_run: Callable[[], int | None],
               on_rows: Callable[[Rows, int], None]) -> Subscription:
    def on_report(rows: Rows, covered: int, run: int | None) -> None:
        ours = current_run()
        if run is None or ours is None or run == ours:
            on_rows(rows, covered)

    return create_parsed_subscription(node, topic, parse, on_report, HELD_QOS)


def subscribe_held_reports(node: Node, current_run: Callable[[], int | None],
                           on_rows: Callable[[Rows, int], None]) -> Subscription:
    """Subscribe ``node`` to ``/pph/notch_held``; ``on_rows(rows, covered)`` for each good one.

    A report of another run than ``current_run()`` (a driver restarted since) is dropped.
    Returns the (raw) subscription, for the node's loop subscriptions (not latest-only:
    every report counts).
    """
    return _subscribe(node, NOTCH_HELD_TOPIC, parse_held_report, current_run, on_rows)


def subscribe_stand_in_reports(node: Node, current_run: Callable[[], int | None],
                               on_rows: Callable[[Rows, int], None]) -> Subscription:
    """Subscribe ``node`` to ``/pph/stand_ins``, as :func:`subscribe_held_reports`."""
    return _subscribe(node, STAND_INS_TOPIC, parse_stand_in_report, current_run, on_rows)
