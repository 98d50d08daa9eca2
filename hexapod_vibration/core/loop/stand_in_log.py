"""The driver's record of the samples whose applied force its controllers did not compute.

In realtime a controller's answer to a due sample can be late: the driver applies a stand-in
(:class:`~hexapod_vibration.core.loop.command_arbiter.CommandArbiter`: the stream's forecast
row, or the command applied before, held). A stand-in that differs from the command the
controller computes for that sample is a step in the force that no controller made: a
one-sample step of 0.02-0.12 N from the pointing forecast lifted one 250-sample block's
100-400 Hz third octaves by 10-20 dB, and the divergence guard faded control out of realtime
runs on such timing faults (``docs/performance.md``). :class:`StandInLog` collects, over
every command stream, the due samples where such a stand-in went in:

- a stand-in is *cleared* when the stream's late command for that sample comes within
  ``wait_samples`` samples and is within ``tolerance_n`` (N, every strut) of what was
  applied (a forecast that was right);
- otherwise it *stood in*: a command that came but differs, or none at all (a controller
  that skipped the sample after a stall, or was later than the wait: its size unknown).

The watchdog's samples (a stale stream's ramp to zero force, its zero force, the ramp back
up: :mod:`~hexapod_vibration.core.loop.stale_fade`) are stand-ins too, marked as such: the
platform answers the loss of a 35 N pointing force for seconds, not for a few samples.

The driver publishes the runs of such samples, complete up to ``covered``, as rows
``(first due, last due, watchdog)`` (``/pph/stand_ins``; ``watchdog`` 1 if any sample of
the run was the watchdog's), so that the notch's guard leaves their blocks out. No ROS
import.
"""

from __future__ import annotations

from collections import deque

import numpy as np

STAND_IN_TOLERANCE_N = 0.005
"""Largest difference (N, any strut) of a stand-in from the late command that makes it a
right one (cleared). The guard replayed on realtime bags held in all 8 runs with the blocks
of stand-ins off by more than this left out (5 of them faded with every block judged)."""

LATE_WAIT_SAMPLES = 20
"""Samples a stand-in waits for its stream's late command before it counts as unknown."""


class StandInLog:
    """Stand-ins of every command stream, settled ``wait_samples`` after their due sample.

    Args:
        tolerance_n: see :data:`STAND_IN_TOLERANCE_N` (N).
        wait_samples: see :data:`LATE_WAIT_SAMPLES` (samples, >= 0).
    """

    def __init__(self, tolerance_n: float = STAND_IN_TOLERANCE_N,
                 wait_samples: int = LATE_WAIT_SAMPLES) -> None:
        """Nothing noted, nothing covered."""
        self.tolerance_n = float(tolerance_n)
        self.wait_samples = int(wait_samples)
        self.covered = -1
        """Every due sample up to this one is settled (-1: none)."""
        self.stood_in = 0
        """Due samples reported as stood in, since the start."""
        self._pending: deque[tuple[int, str, np.ndarray, bool]] = deque()
        self._cleared: set[tuple[int, str]] = set()
        self._rows: list[list[int]] = []
        self._due = -1
        self._last_stood_in = -1

    def note(self, due: int, stream: str, force_n: np.ndarray, watchdog: bool = False) -> None:
        """At due sample ``due`` stream ``stream``'s answer was late; ``force_n`` went in.

        ``watchdog``: the force was the watchdog's (its ramp or zero force).
        """
        self._pending.append((int(due), stream, np.array(force_n, dtype=float),
                              bool(watchdog)))

    def answered(self, stream: str, index: int, command_n: np.ndarray) -> None:
        """Stream ``stream``'s command for sample ``index`` was accepted (any time).

        A command for a due sample with a pending stand-in clears it if within the
        tolerance of what was applied.
        """
        if index > self._due:
            return
        for due, name, force_n, _ in self._pending:
            if due == index and name == stream:
                if np.max(np.abs(np.asarray(command_n) - force_n)) <= self.tolerance_n:
                    self._cleared.add((due, name))
                return

    def settle(self, due: int) -> None:
        """The driver is at due sample ``due``: settle the stand-ins ``wait_samples`` older.

        Called once per sample, after the sample's :meth:`note` calls.
        """
        self._due = int(due)
        settled = self._due - self.wait_samples
        pending = self._pending
        while pending and pending[0][0] <= settled:
            sample, name, _, watchdog = pending.popleft()
            if (sample, name) in self._cleared:
                self._cleared.discard((sample, name))
            else:
                self._add_row(sample, watchdog)
        self.covered = max(self.covered, settled)

    def _add_row(self, sample: int, watchdog: bool) -> None:
        rows = self._rows
        if sample <= self._last_stood_in:           # another stream at the same sample
            if watchdog and rows and rows[-1][1] == sample:
                rows[-1][2] = 1
            return
        self._last_stood_in = sample
        self.stood_in += 1
        if rows and rows[-1][1] == sample - 1:
            rows[-1][1] = sample
            rows[-1][2] |= int(watchdog)
        else:
            rows.append([sample, sample, int(watchdog)])

    def drain(self) -> list[tuple[int, int, int]]:
        """The runs ``(first due, last due, watchdog)`` settled since the last drain.

        Oldest first; ``watchdog`` 1 if any of the run's samples was the watchdog's.
        """
        rows, self._rows = self._rows, []
        return [(first, last, watchdog) for first, last, watchdog in rows]
