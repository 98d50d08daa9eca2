"""The forecasts of a command stream, for the samples whose command comes late.

A controller may publish, beside its command of sample n, what it will command at the next
samples (:mod:`hexapod_vibration.core.control.command_forecast`). A realtime driver keeps,
per sample, the row of the newest forecast covering it; when the stream's command for the
sample due is not there,
:class:`~hexapod_vibration.core.loop.command_arbiter.CommandArbiter` applies that row
instead of holding the previous command. Rows are kept per sample, not per forecast: a
forecast published after a late command starts after that command's sample, so keeping
only the newest forecast would leave the late sample uncovered.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.contract import STRUT_COUNT

CAPACITY_SAMPLES = 512
"""Samples of rows kept (a ring); a forecast longer than this keeps its first ones."""


class ForecastBuffer:
    """Forecast forces (N) by sample, from the newest forecast covering each sample."""

    def __init__(self, channels: int = STRUT_COUNT) -> None:
        """No forecast yet; rows of ``channels`` forces."""
        self.first = -1
        """The first sample of the newest forecast taken (-1: none yet)."""
        self._rows = np.zeros((CAPACITY_SAMPLES, int(channels)))
        self._samples = np.full(CAPACITY_SAMPLES, -1, dtype=np.int64)
        self.applied = 0
        """Rows applied in place of a late command (counted by the arbiter)."""

    def take(self, first: int, rows: np.ndarray) -> bool:
        """Keep ``rows`` ((K, C) N) for samples ``first``... unless an as new one was taken."""
        if first <= self.first:
            return False
        rows = np.asarray(rows, dtype=float)[:CAPACITY_SAMPLES]
        samples = first + np.arange(rows.shape[0])
        slots = samples % CAPACITY_SAMPLES
        self._rows[slots] = rows
        self._samples[slots] = samples
        self.first = int(first)
        return True

    def row(self, sample: int) -> np.ndarray | None:
        """The forecast force (N, (C,)) for ``sample``, None if no forecast covers it."""
        slot = sample % CAPACITY_SAMPLES
        if sample < 0 or self._samples[slot] != sample:
            return None
        return self._rows[slot].copy()
