"""The notch controller's end of the driver's reports: held commands and stand-ins.

A realtime driver reports, every 100 samples, the runs of due samples whose notch command it
did not apply (``contract.NOTCH_HELD_TOPIC``) and those where a stand-in no controller
computed went in (``contract.STAND_INS_TOPIC``). :func:`subscribe_held_reports` and
:func:`subscribe_stand_in_reports` check each report (its bytes, its label, whole rows, its
run) and hand the rows to the controller, those it has not had only (each report repeats
the rows of the reports before it: :mod:`~hexapod_vibration.core.loop.repeated_reports`); a
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

from hexapod_vibration.contract import (
    HELD_ROWS_LABEL,
    NOTCH_HELD_TOPIC,
    STAND_IN_ROWS_LABEL,
    STAND_INS_TOPIC,
    InvalidStrutMessage,
)
from hexapod_vibration.core.loop.repeated_reports import FreshRows
from hexapod_vibration.ros.messages import create_parsed_subscription, parse_labelled_sample
from hexapod_vibration.ros.qos import HELD_QOS

Rows = list[tuple[int | float, ...]]


def _parse_rows(msg: Float64MultiArray, label: str, indices: int, last: str
                ) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a report of rows ``(first due, last due, ...)``.

    Each row has ``indices`` sample indices (integers >= -1), then its ``last`` column:
    ``"gain"`` (a float in [0, 1]) or ``"flag"`` (0 or 1, an int).

    Raises:
        InvalidStrutMessage: another label, not whole rows of that form, a row whose due
            samples are not ``0 <= first <= last``, no sample label.
    """
    columns = indices + 1
    sample = parse_labelled_sample(msg, label, columns)
    table = sample.values.reshape(-1, columns)
    index_part, extra = table[:, :indices], table[:, indices]
    if np.any(index_part != np.round(index_part)) or np.any(index_part < -1):
        raise InvalidStrutMessage(f"expected rows of {indices} sample indices and a {last}, "
                                  f"got {sample.values.size} values")
    allowed = (extra >= 0.0) & (extra <= 1.0) if last == "gain" else (extra == 0) | (extra == 1)
    if not np.all(allowed):
        raise InvalidStrutMessage(f"a row's {last} is not "
                                  f"{'in [0, 1]' if last == 'gain' else '0 or 1'}")
    kind = float if last == "gain" else int
    rows = [(*(int(v) for v in row[:indices]), kind(row[indices])) for row in table]
    if any(row[0] < 0 or row[1] < row[0] for row in rows):
        raise InvalidStrutMessage("a row's due samples are not first <= last, both >= 0")
    return rows, sample.index, sample.run


def parse_held_report(msg: Float64MultiArray) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a ``/pph/notch_held`` message.

    Rows ``(first due, last due, applied, gain)``.
    """
    return _parse_rows(msg, HELD_ROWS_LABEL, 3, "gain")


def parse_stand_in_report(msg: Float64MultiArray) -> tuple[Rows, int, int | None]:
    """``(rows, covered, run)`` of a ``/pph/stand_ins`` message.

    Rows ``(first due, last due, watchdog)``.
    """
    return _parse_rows(msg, STAND_IN_ROWS_LABEL, 2, "flag")


def _subscribe(node: Node, topic: str, parse: Callable, current_run: Callable[[], int | None],
               on_rows: Callable[[Rows, int], None]) -> Subscription:
    fresh_rows = FreshRows()

    def on_report(rows: Rows, covered: int, run: int | None) -> None:
        ours = current_run()
        if run is None or ours is None or run == ours:
            fresh = fresh_rows.take(rows, covered, run)
            if fresh is not None:
                on_rows(fresh, covered)

    return create_parsed_subscription(node, topic, parse, on_report, HELD_QOS)


def subscribe_held_reports(node: Node, current_run: Callable[[], int | None],
                           on_rows: Callable[[Rows, int], None]) -> Subscription:
    """Subscribe ``node`` to ``/pph/notch_held``; ``on_rows(rows, covered)`` for each good one.

    ``rows``: those not had from an earlier report. A report of another run than
    ``current_run()`` (a driver restarted since) is dropped, as is one older than the last.
    Returns the (raw) subscription, for the node's loop subscriptions (not latest-only:
    every report counts).
    """
    return _subscribe(node, NOTCH_HELD_TOPIC, parse_held_report, current_run, on_rows)


def subscribe_stand_in_reports(node: Node, current_run: Callable[[], int | None],
                               on_rows: Callable[[Rows, int], None]) -> Subscription:
    """Subscribe ``node`` to ``/pph/stand_ins``, as :func:`subscribe_held_reports`."""
    return _subscribe(node, STAND_INS_TOPIC, parse_stand_in_report, current_run, on_rows)
