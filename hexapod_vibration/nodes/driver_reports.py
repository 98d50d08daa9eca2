"""What a realtime driver reports, every 100 samples, on the commands it applied.

- ``/pph/notch_held``: the notch commands it held (:class:`~hexapod_vibration.core.loop.
  held_log.HeldLog`), for the identification's record of the input that went in;
- ``/pph/stand_ins``: the due samples where a stand-in some controller did not compute went
  in (:class:`~hexapod_vibration.core.loop.stand_in_log.StandInLog`), so that the notch's
  divergence guard judges control on the blocks its commands were applied in.

Both best effort, each report with the rows of the reports before it
(:mod:`~hexapod_vibration.core.loop.repeated_reports`).

Lockstep applies every command when due (or counts the sample as missed): no report.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.cdr import encode_vector_cdr
from hexapod_vibration.contract import (
    HELD_REPORT_EVERY_SAMPLES,
    HELD_ROWS_LABEL,
    NOTCH_HELD_TOPIC,
    STAND_IN_ROWS_LABEL,
    STAND_INS_TOPIC,
)
from hexapod_vibration.core.loop.command_arbiter import CommandArbiter
from hexapod_vibration.core.loop.held_log import HeldLog
from hexapod_vibration.core.loop.repeated_reports import RepeatedRows
from hexapod_vibration.core.loop.stand_in_log import StandInLog
from hexapod_vibration.ros.qos import HELD_QOS
from hexapod_vibration.ros.rclpy_internals import serialized_publish


class DriverReports:
    """The held-command and stand-in logs of a realtime driver, and their publishers."""

    def __init__(self, node: Node) -> None:
        """Create the two publishers; nothing noted."""
        def publisher(topic: str):
            return serialized_publish(node.create_publisher(Float64MultiArray, topic,
                                                            HELD_QOS))
        self.held_log = HeldLog()
        self.stand_in_log = StandInLog()
        self._reports = (
            (self.held_log, RepeatedRows(), publisher(NOTCH_HELD_TOPIC), HELD_ROWS_LABEL),
            (self.stand_in_log, RepeatedRows(), publisher(STAND_INS_TOPIC), STAND_IN_ROWS_LABEL))

    def answered(self, stream: str, index: int, command_n: np.ndarray) -> None:
        """A command of ``stream`` for sample ``index`` was accepted (clears a right stand-in)."""
        self.stand_in_log.answered(stream, index, command_n)

    def note(self, arbiter: CommandArbiter, forces: dict[str, np.ndarray], run: int) -> None:
        """Log what the sample just closed applied; every 100 samples publish both reports.

        Called once per sample, after ``arbiter.close_sample`` returned ``forces`` (N).
        """
        due, notch = arbiter.due, arbiter.streams["notch"]
        self.held_log.note(due, notch.applied, notch.fade.gain)
        stand_ins = self.stand_in_log
        for name, stream in arbiter.streams.items():
            if stream.stood_in and due >= 0:
                stand_ins.note(due, name, forces[name], watchdog=not stream.fade.full)
        stand_ins.settle(due)
        if arbiter.sample % HELD_REPORT_EVERY_SAMPLES:
            return
        for log, repeated, publish, label in self._reports:
            if log.covered >= 0:
                flat = [float(v) for row in repeated.rows(log.drain()) for v in row]
                publish(encode_vector_cdr(flat, log.covered, run, label=label))
