"""The driver's 10 Hz reports sent best effort, each with the rows of the reports before it.

A realtime driver reports every 100 samples the rows it logged since the report before
(``/pph/notch_held``, ``/pph/stand_ins``). Sent RELIABLE, a report lost on the way (a
controller stopped for 350 ms: its socket's buffer overflows with the 1 kHz traffic) is
repaired only at the writer's next heartbeat, and every later report waits for it in order:
the notch got its reports 1.1-3 s late after such a stall (a bare rclpy pair: 1.1 s; the
notch in ``single_tone_harmonic``: 3.1 s), its guard judged the platform's answer to the
stall unmarked and faded control out. Sent BEST_EFFORT, the reports after the stall come at
once (the same pair: 0 ms) and a lost one is gone: so each report carries the rows of the
last :data:`REPEAT_REPORTS` reports (:class:`RepeatedRows`), and the reader takes only the
rows it has not had, by their due samples (:class:`FreshRows`: a report's rows lie after
the report before's ``covered``). No ROS import.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

REPEAT_REPORTS = 10
"""Reports whose rows each report repeats (1 s at 10 Hz): a reader that lost fewer than this
many in a row loses no row."""

Row = tuple
"""A report's row: ``(first due, last due, ...)``."""


class RepeatedRows:
    """The rows a report sends: its own and those of the reports before it."""

    def __init__(self, repeat: int = REPEAT_REPORTS) -> None:
        """Nothing reported yet; each report repeats ``repeat`` - 1 reports before it."""
        self._reports: deque[list[Row]] = deque(maxlen=int(repeat))

    def rows(self, new: Sequence[Row]) -> list[Row]:
        """The rows of the report to send: those of the last reports, then ``new``."""
        self._reports.append(list(new))
        return [row for report in self._reports for row in report]


class FreshRows:
    """A reader's filter: the rows of a report it has not had, by due sample."""

    def __init__(self) -> None:
        """No report yet."""
        self.covered = -1
        """The last due sample the reports taken are complete up to (-1: none)."""
        self.run: int | None = None

    def take(self, rows: Sequence[Row], covered: int, run: int | None
             ) -> list[Row] | None:
        """The rows of this report after those already taken; None for an old report.

        A report of another run than the last one starts afresh (a restarted driver).
        """
        if run != self.run:
            self.run, self.covered = run, -1
        if covered <= self.covered:
            return None
        fresh = [row for row in rows if row[0] > self.covered]
        self.covered = int(covered)
        return fresh
