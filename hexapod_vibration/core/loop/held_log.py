"""The driver's record of the commands it held, reported to the controller that sent them.

At each sample the driver applies the answer to the sample due (``CommandArbiter.due``); a
late one is replaced by the command applied before it, or by zero force once the stream is
stale. :class:`HeldLog` collects, for one stream, the runs of due samples whose answer was
not applied, as rows ``(first due, last due, applied sample)`` (-1: zero force), and up to
which due sample it is complete; the driver publishes them (``/pph/notch_held``) so that an
identification knows the input that really went in
(:mod:`hexapod_vibration.core.control.held_inputs`). No ROS import.
"""

from __future__ import annotations

ZERO_FORCE = -1
"""The ``applied`` of a row whose samples got zero force (a stale stream)."""


class HeldLog:
    """Runs of held commands of one stream since the last :meth:`drain`."""

    def __init__(self) -> None:
        """Nothing held, nothing covered."""
        self.covered = -1
        """The last due sample noted (-1: none)."""
        self._rows: list[list[int]] = []

    def note(self, due: int, applied: int, stale: bool) -> None:
        """At due sample ``due`` the stream's command of sample ``applied`` was in force.

        ``stale``: zero force was applied instead (the watchdog). Before any due sample
        (``due < 0``) nothing is noted.
        """
        if due < 0:
            return
        self.covered = due
        if applied == due and not stale:
            return
        applied = ZERO_FORCE if stale else applied
        rows = self._rows
        if rows and rows[-1][1] == due - 1 and rows[-1][2] == applied:
            rows[-1][1] = due
        else:
            rows.append([due, due, applied])

    def drain(self) -> list[tuple[int, int, int]]:
        """The rows noted since the last drain (oldest first), then forgets them."""
        rows, self._rows = self._rows, []
        return [(first, last, applied) for first, last, applied in rows]
