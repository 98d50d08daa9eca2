"""The samples the divergence guard judges: straight on, or after the driver's stand-in reports.

A realtime driver reports, every 100 samples, the due samples where a force no controller
computed went in (``/pph/stand_ins``, :mod:`hexapod_vibration.core.loop.stand_in_log`): a
timing fault of the loop, not something control did. Such a step lifts one block's quiet
third octaves by 10-20 dB, and the guard faded control out of realtime runs for it
(replayed on six faded runs' bags: at the run's own sample in five; with those blocks left
out, all held: ``docs/performance.md``).

:class:`GuardFeed` passes each sample to the guard at once until a first report comes.
From then on it holds the samples until the reports cover them (their due samples plus the
command delay) and marks each sample a stand-in disturbed (the applied sample and the
platform's next ``KICK_SAMPLES`` answers; after a run of the watchdog's, a stream's ramp to
zero force and back, the next ``WATCHDOG_SETTLE_SAMPLES``): the guard leaves such a sample's
block out, as one with samples missing. The verdicts come up to one report later
(<= ~0.15 s); samples not covered after ``MAX_HELD_SAMPLES`` (reports that stopped) go on
unmarked. Lockstep and the core loop have no reports: their guard is exactly the one
without this. No ROS import.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.control.divergence_guard import DivergenceGuard, GuardVerdict

KICK_SAMPLES = 2
"""Samples after a stand-in's applied sample that are marked too (the platform's answer)."""

WATCHDOG_SETTLE_SAMPLES = 3000
"""Samples after a run of the watchdog's that are marked too: the platform's answer to a lost
pointing force. Measured (``single_tone_harmonic`` in realtime, both controllers stopped
for 350 ms under control; the six accelerations' power in 8-500 Hz per 250-ms block
against the blocks before): +45 dB at the end of the ramp back up (+51 dB with a step),
falling ~20 dB/s, within 3.5 dB 2.25 s later in both runs; the third octaves >= 50 Hz
off the tones within 3 dB after 1 s with the ramp. The guard judged those blocks as
control's doing: lower_mu (+9.7 dB broadband) or, through the weights' re-convergence,
the line-offset check faded control out."""

MAX_HELD_SAMPLES = 2000
"""Most samples held for the reports (2 s at 1 kHz); older ones go on unmarked. A controller
that stalled catches up on its queue of samples before the reports on them come: with 500
(0.5 s) a 350 ms stall of both controllers under control let the platform's answer through
unmarked, and the guard faded control out on it."""


class GuardFeed:
    """Feeds ``guard``, held back for the driver's stand-in reports once they come."""

    def __init__(self, guard: DivergenceGuard) -> None:
        """No report yet: samples go straight to ``guard``."""
        self.guard = guard
        self.reported = False
        """True once a stand-in report came (a realtime driver)."""
        self.covered = -1
        """The last sample index whose stand-ins are known (-1: none)."""
        self.stand_in_samples = 0
        """Samples the guard got marked as stand-in disturbed."""
        self.watchdog_samples = 0
        """Of those, the samples marked for a run of the watchdog's (and its settling)."""
        self._rows: deque[tuple[int, int]] = deque()
        self._watchdog_rows: deque[tuple[int, int]] = deque()
        self._held: deque[tuple[int, np.ndarray, bool, bool]] = deque()

    def note(self, rows: Sequence[tuple[int, int, int]], covered: int,
             delay_samples: int) -> list[tuple[int, int]]:
        """A report: stand-ins at due samples ``rows`` (first, last, watchdog), to ``covered``.

        ``delay_samples``: the driver's command delay (due sample j is applied at j + d).
        Returns the samples marked for the watchdog's runs, ``(first, last)`` each (the
        run applied and the platform's settling).
        """
        self.reported = True
        d = int(delay_samples)
        watchdog_marks = []
        for first, last, watchdog in rows:
            marked = (first + d, last + d + (WATCHDOG_SETTLE_SAMPLES if watchdog
                                             else KICK_SAMPLES))
            self._rows.append(marked)
            if watchdog:
                watchdog_marks.append(marked)
        self._watchdog_rows.extend(watchdog_marks)
        self.covered = max(self.covered, int(covered) + d)
        return watchdog_marks

    def step(self, error: np.ndarray, recording: bool, judging: bool,
             index: int) -> list[tuple[GuardVerdict, int]]:
        """Take sample ``index``; the verdicts (with their sample) of the samples released."""
        if not self.reported:
            verdict = self.guard.step(error, recording, judging, index=index)
            return [] if verdict is None else [(verdict, index)]
        self._held.append((int(index), np.array(error, dtype=float), recording, judging))
        verdicts = []
        held = self._held
        while held and (held[0][0] <= self.covered or len(held) > MAX_HELD_SAMPLES):
            n, e, rec, judge = held.popleft()
            stood_in, watchdog = self._disturbed(n)
            self.stand_in_samples += stood_in
            self.watchdog_samples += watchdog
            verdict = self.guard.step(e, rec, judge, index=n, stood_in=stood_in)
            if verdict is not None:
                verdicts.append((verdict, n))
        return verdicts

    @property
    def held_samples(self) -> int:
        """Samples held for the reports now."""
        return len(self._held)

    def _disturbed(self, n: int) -> tuple[bool, bool]:
        """Sample ``n`` is within a reported stand-in's marked samples; within a watchdog's."""
        return _marks(self._rows, n), _marks(self._watchdog_rows, n)

    def clear(self) -> None:
        """Drop the held samples (the tones, the reference or the run start again)."""
        self._held.clear()

    def restart(self) -> None:
        """A new run of the loop: no report, nothing held, samples straight on again."""
        self.clear()
        self._rows.clear()
        self._watchdog_rows.clear()
        self.reported, self.covered = False, -1


def _marks(rows: deque[tuple[int, int]], n: int) -> bool:
    """Sample ``n`` is within one of ``rows``; the spans ending before ``n`` are dropped.

    ``rows``: marked spans, starts in order (a watchdog's long settling may cover the rows
    after it).
    """
    while rows and rows[0][1] < n:
        rows.popleft()
    return bool(rows) and rows[0][0] <= n
