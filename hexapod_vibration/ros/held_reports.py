"""The notch controller's end of ``/pph/notch_held``: the commands the driver held.

A realtime driver reports, every 100 samples, the runs of due samples whose notch command it
did not apply (``contract.NOTCH_HELD_TOPIC``). :func:`subscribe_held_reports` checks each
report (its bytes, its label, whole rows, its run) and hands the rows to the controller; a
bad one is refused with a throttled warning and changes nothing. The subscription is one of
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

from hexapod_vibration.contract import HELD_ROWS_LABEL, NOTCH_HELD_TOPIC, InvalidStrutMessage
from hexapod_vibration.ros.messages import create_parsed_subscription, parse_labelled_sample
from hexapod_vibration.ros.qos import HELD_QOS

Rows = list[tuple[int, int, int]]


def parse_held_report(msg: Float64MultiArray) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a ``/pph/notch_held`` message.

    Raises:
        InvalidStrutMessage: another label, not whole rows of integers, no sample label.
    """
    sample = parse_labelled_sample(msg, HELD_ROWS_LABEL, 3)
    values = sample.values
    if np.any(values != np.round(values)) or np.any(values < -1):
        raise InvalidStrutMessage(f"expected rows of 3 sample indices, got {values.size} "
                                  "values")
    rows = [(int(a), int(b), int(c)) for a, b, c in values.reshape(-1, 3)]
    if any(first < 0 or last < first for first, last, _ in rows):
        raise InvalidStrutMessage("a row's due samples are not first <= last, both >= 0")
    return rows, sample.index, sample.run


def subscribe_held_reports(node: Node, current_run: Callable[[], int | None],
                           on_rows: Callable[[Rows, int], None]) -> Subscription:
    """Subscribe ``node`` to the reports; ``on_rows(rows, covered)`` for each good one.

    A report of another run than ``current_run()`` (a driver restarted since) is dropped.
    Returns the (raw) subscription, for the node's loop subscriptions (not latest-only:
    every report counts).
    """
    def on_report(rows: Rows, covered: int, run: int | None) -> None:
        ours = current_run()
        if run is None or ours is None or run == ours:
            on_rows(rows, covered)

    return create_parsed_subscription(node, NOTCH_HELD_TOPIC, parse_held_report, on_report,
                                      HELD_QOS)
