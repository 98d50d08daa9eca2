"""The driver's record of the commands it held, reported to the controller that sent them.

At each sample the driver applies the answer to the sample due (``CommandArbiter.due``); a
late one is replaced by the command applied before it, and the watchdog's gain
(:mod:`~hexapod_vibration.core.loop.stale_fade`) scales a stale stream's force down to zero
and back up. :class:`HeldLog` collects, for one stream, the runs of due samples whose answer
was not applied as it was, as rows ``(first due, last due, applied sample, gain)``: the
force that went in was ``gain`` times the command of sample ``applied`` (-1: none yet, zero
force). It knows up to which due sample it is complete; the driver publishes them
(``/pph/notch_held``) so that an identification knows the input that really went in
(:mod:`hexapod_vibration.core.control.held_inputs`). No ROS import.
"""

from __future__ import annotations

NO_COMMAND = -1
"""The ``applied`` of a row whose samples got no command at all (none had come yet)."""


class HeldLog:
    """Runs of held or scaled commands of one stream since the last :meth:`drain`."""

    def __init__(self) -> None:
        """Nothing held, nothing covered."""
        self.covered = -1
        """The last due sample noted (-1: none)."""
        self._rows: list[list] = []

    def note(self, due: int, applied: int, gain: float) -> None:
        """At due sample ``due``, ``gain`` (0..1) times the command of ``applied`` went in.

        Before any due sample (``due < 0``) nothing is noted; before any command
        (``applied`` -1) the force was zero whatever the gain (noted as 0).
        """
        if due < 0:
            return
        self.covered = due
        if applied == due and gain == 1.0:
            return
        if applied == NO_COMMAND:
            gain = 0.0
        rows = self._rows
        if rows and rows[-1][1] == due - 1 and rows[-1][2] == applied and rows[-1][3] == gain:
            rows[-1][1] = due
        else:
            rows.append([due, due, applied, gain])

    def drain(self) -> list[tuple[int, int, int, float]]:
        """The rows noted since the last drain (oldest first), then forgets them."""
        rows, self._rows = self._rows, []
        return [(first, last, applied, gain) for first, last, applied, gain in rows]
