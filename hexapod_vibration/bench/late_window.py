"""Late commands of a realtime loop with control in force, apart from its start.

A realtime run's late commands (the driver's ``late_commands``: samples whose command was
not back by their deadline) have two sources of very different kinds:

- the start: the handshake, and above all the analysis of the notch's 10 s broadband
  identification (G(f), its disturbance lines, the Nyquist tests of the mu policy), pieces
  of 0.1-0.35 s run on the notch's loop thread: about 0.8 s of samples answered late or not
  at all (measured 2026-12-05: 812 of 863 late commands of a 55 s FIFO run). The canceller
  is off and frozen then, so the command the driver applies instead (the notch's forecast,
  or its last command) is the one the notch would have sent;
- the rest, with control in force: the loop's steady lateness.

:class:`LateWindow` follows the graph's ``/diagnostics`` (a ``tools.graph_monitor.
GraphMonitor``) and counts the second apart: from the first driver report at or after the
sample where the notch said its control is in force (state ``adapting``), or, if it never
is, from where the caller starts it (live, the rule of ``analysis/late_commands.late_since``,
which the report applies from control-on). No ROS import: it reads the monitor's
dictionaries.
"""

from __future__ import annotations

from typing import Any

from hexapod_vibration.analysis.late_commands import driver_counts
from hexapod_vibration.contract import NotchState

SETTLED_STATES = (NotchState.ADAPTING.value, NotchState.REFUSED.value)
"""Notch states that end the start: control in force, or refused (its identification over)."""


class LateWindow:
    """Late commands and samples from a starting driver report to the latest one.

    Args:
        watch: the graph monitor (``driver`` and ``notch``: their latest status values).
    """

    def __init__(self, watch: Any) -> None:
        """Not started."""
        self._watch = watch
        self._settled_at: int | None = None
        self.start: tuple[int, int] | None = None
        """(samples, late commands) of the driver's report the window starts at."""
        self.settled = False
        """True if the window starts where the notch's identification was over."""

    def _driver(self) -> tuple[int, int, int]:
        """(sample, samples, late commands) of the driver's latest report."""
        return driver_counts(self._watch.driver)

    def follow(self) -> bool:
        """Call after each spin; True once the window started.

        It starts at the first driver report from the sample where the notch settled.
        """
        if self.start is not None:
            return True
        notch = self._watch.notch
        if self._settled_at is None and notch.get("state") in SETTLED_STATES:
            self._settled_at = int(notch.get("last_sample", 0))
        sample, samples, late = self._driver()
        if self._settled_at is not None and sample >= self._settled_at:
            self.start, self.settled = (samples, late), True
        return self.start is not None

    def start_now(self) -> tuple[int, int]:
        """(Re)start at the driver's latest report; its (samples, late commands).

        ``settled`` stays as :meth:`follow` found it: False if the notch had not settled.
        """
        _, samples, late = self._driver()
        self.start = (samples, late)
        return self.start

    def counts(self) -> tuple[int, int]:
        """(samples, late commands) since the start (0, 0 before it)."""
        if self.start is None:
            return 0, 0
        _, samples, late = self._driver()
        return samples - self.start[0], late - self.start[1]

    def report(self) -> dict[str, Any]:
        """The window's counts for results.json: samples, late, fraction, settled."""
        samples, late = self.counts()
        return {"control_samples": samples, "control_late": late,
                "control_missed_fraction": late / samples if samples > 0 else float("nan"),
                "control_settled": self.settled}
