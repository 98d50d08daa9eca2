"""Percentiles of a loop's wall-clock times over its last minute, at O(1) per sample.

The driver times every sample (the period between two publications, the latency from a
publication to its notch command) and reports percentiles on ``/diagnostics`` once a
second. Sorting the last 60 000 values there took 5.3 ms (a deque made into an array, two
percentiles each of two windows; measured on the project's 2-core machine): the realtime
loop missed the samples after every whole second. :class:`RollingPercentiles` counts the
values into fixed bins instead (10 us wide up to 20 ms, 1 % wide beyond), one histogram
per block of :data:`BLOCK_VALUES` values, the last :data:`BLOCKS` blocks kept and summed
as they come and go, so a report is a cumulative sum over the bins: the driver's whole
report (:meth:`CommandArbiter.report`) takes 0.18 ms instead of 5.3 ms. The block being
filled counts only the bins it touched (a dict): made into an array of every bin, it cost
80 us a report and again at each block's end.

A percentile is the upper edge of the bin it falls in: it is never below the exact value
and at most one bin width (10 us below 20 ms) above it; the maximum is exact.
"""

from __future__ import annotations

import math

import numpy as np

FINE_WIDTH_MS = 0.01
"""Width (ms) of the bins below :data:`FINE_LIMIT_MS`."""
FINE_LIMIT_MS = 20.0
"""Upper edge (ms) of the fine bins; above it bins grow by :data:`COARSE_RATIO` each."""
COARSE_RATIO = 1.01
COARSE_BINS = 1200
"""Bins above the fine ones: up to 20 ms x 1.01^1200, about 3 000 s; beyond: the last bin."""
BLOCK_VALUES = 1000
"""Values per histogram block (1 s of samples at 1 kHz)."""
BLOCKS = 60
"""Blocks kept: the percentiles are those of the last 59 000 to 60 000 values."""

_FINE_BINS = round(FINE_LIMIT_MS / FINE_WIDTH_MS)
_LOG_RATIO = math.log(COARSE_RATIO)
UPPER_EDGES_MS = np.concatenate([
    FINE_WIDTH_MS * np.arange(1, _FINE_BINS + 1),
    FINE_LIMIT_MS * COARSE_RATIO ** np.arange(1, COARSE_BINS + 1)])
"""Upper edge (ms) of every bin, the value a percentile in that bin is reported as."""


def bin_of(value_ms: float) -> int:
    """The bin of a time (ms, >= 0; negative ones go to the first bin)."""
    if value_ms < FINE_LIMIT_MS:
        return max(int(value_ms / FINE_WIDTH_MS), 0)
    coarse = int(math.log(value_ms / FINE_LIMIT_MS) / _LOG_RATIO)
    return _FINE_BINS + min(coarse, COARSE_BINS - 1)


class RollingPercentiles:
    """Percentiles (ms) of the last :data:`BLOCKS` x :data:`BLOCK_VALUES` values added."""

    def __init__(self) -> None:
        """An empty window."""
        self._blocks = np.zeros((BLOCKS, UPPER_EDGES_MS.size), dtype=np.int64)
        self._kept = np.zeros(UPPER_EDGES_MS.size, dtype=np.int64)   # the blocks' sum
        self._block_max = np.full(BLOCKS, -math.inf)
        self._current: dict[int, int] = {}         # bin -> count, the block being filled
        self._current_count = 0
        self._current_max = -math.inf
        self._next_block = 0
        self.count = 0
        """Values added since the start (all time, not only the window)."""

    def __len__(self) -> int:
        """Values in the window."""
        return int(self._kept.sum()) + self._current_count

    def add(self, value_ms: float) -> None:
        """Count one value (ms); every :data:`BLOCK_VALUES` values a block closes."""
        current, b = self._current, bin_of(value_ms)
        current[b] = current.get(b, 0) + 1
        self._current_max = max(self._current_max, value_ms)
        self._current_count += 1
        self.count += 1
        if self._current_count == BLOCK_VALUES:
            self._close_block()

    def _close_block(self) -> None:
        k = self._next_block
        self._kept -= self._blocks[k]
        bins, counts = self._current_block()
        self._blocks[k] = 0
        self._blocks[k, bins] = counts
        self._kept += self._blocks[k]
        self._block_max[k] = self._current_max
        self._next_block = (k + 1) % BLOCKS
        self._current = {}
        self._current_count, self._current_max = 0, -math.inf

    def percentiles(self, qs: tuple[float, ...]) -> list[float]:
        """The ``qs`` percentiles (0..100) of the window (ms), NaN while it is empty.

        The value of rank ceil(q/100 x count) (the nearest-rank definition), reported as
        the upper edge of its bin.
        """
        counts = self._kept.copy()
        bins, current = self._current_block()
        counts[bins] += current
        total = int(counts.sum())
        if total == 0:
            return [math.nan] * len(qs)
        cumulative = np.cumsum(counts)
        ranks = np.maximum(np.ceil(np.asarray(qs, dtype=float) / 100.0 * total), 1)
        bins = np.searchsorted(cumulative, ranks)
        return [float(UPPER_EDGES_MS[b]) for b in bins]

    def _current_block(self) -> tuple[np.ndarray, np.ndarray]:
        """The bins the block being filled touched (each once) and their counts."""
        touched = len(self._current)
        return (np.fromiter(self._current.keys(), np.intp, touched),
                np.fromiter(self._current.values(), np.int64, touched))

    def maximum(self) -> float:
        """The largest value of the window (ms, exact), NaN while it is empty."""
        largest = max(float(self._block_max.max()), self._current_max)
        return largest if math.isfinite(largest) else math.nan
