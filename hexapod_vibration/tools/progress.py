"""The progress line of a run: sim time, ETA, loop rate and what the runner waits for."""

from __future__ import annotations

import math
import sys
import time
from typing import Any


class Progress:
    """Progress of a run: one updating line with an ETA on a terminal, plain lines otherwise.

    The ETA extrapolates the sim time's rate over the run so far (wall s per sim s).
    """

    TTY_PERIOD_S = 0.5
    PLAIN_PERIOD_S = 5.0

    def __init__(self, name: str, duration_s: float, stream: Any = None) -> None:
        """Report on ``stream`` (default stdout) for a run of ``duration_s`` sim seconds."""
        self.name, self.duration_s = name, duration_s
        self.stream = stream or sys.stdout
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._start: tuple[float, float] | None = None
        self._last = -math.inf
        self._shown = False

    def line(self, sim_s: float, rate_hz: str | None, state: str, what: str, now: float
             ) -> str:
        """The progress text at wall time ``now`` (monotonic s)."""
        if self._start is None or sim_s < self._start[1]:
            self._start = (now, sim_s)
        wall0, sim0 = self._start
        speed = (sim_s - sim0) / (now - wall0) if now > wall0 and sim_s > sim0 else 0.0
        eta = (f"ETA {_duration_text((self.duration_s - sim_s) / speed)}" if speed > 0
               else "ETA -")
        try:
            rate = f"{float(rate_hz):.0f} samples/s"
        except (TypeError, ValueError):
            rate = "- samples/s"
        return (f"  [{self.name}] sim {sim_s:5.1f} / {self.duration_s:g} s "
                f"({100 * min(sim_s / self.duration_s, 1.0):3.0f} %), {eta}, loop {rate}, "
                f"notch {state}: {what}")

    def update(self, sim_s: float, rate_hz: str | None, state: str, what: str) -> None:
        """Show the progress (rate-limited)."""
        now = time.monotonic()
        text = self.line(sim_s, rate_hz, state, what, now)
        if now - self._last < (self.TTY_PERIOD_S if self.tty else self.PLAIN_PERIOD_S):
            return
        self._last = now
        if self.tty:
            self.stream.write(f"\r{text}\x1b[K")
            self._shown = True
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def clear(self) -> None:
        """End the updating line (terminal only) so that other output starts clean."""
        if self._shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._shown = False


def _duration_text(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    return f"{seconds // 60}:{seconds % 60:02d}"
