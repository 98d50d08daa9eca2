"""Which loop sample the supervisor is at, and the samples it did not get.

The supervisor counts what it sees of the sample indices: ``gaps`` (how many times samples
were missing) and ``missed_samples`` (how many), and ``duplicates`` (samples at or before
the last one, not used). For the notch node these counts are the ones on ``/diagnostics``:
the supervisor acts on the gaps (the oscillators' phases, a running identification), in the
node and in the core loop alike.
"""

from __future__ import annotations


class SampleClock:
    """The first and last sample taken, and the counts of missing and repeated ones."""

    def __init__(self) -> None:
        """No sample yet (``first`` and ``last`` are -1)."""
        self.first = -1
        self.last = -1
        self.observed = -1
        """The last sample observed but not taken (a loop behind skipped it)."""
        self.counters = {"gaps": 0, "missed_samples": 0, "duplicates": 0}

    def take(self, index: int) -> int | None:
        """Take sample ``index``: the number of samples missing before it, or None.

        None: the sample is not after the last one taken (a duplicate or out of order),
        counted and not to be used.
        """
        if index <= self.last:
            self.counters["duplicates"] += 1
            return None
        gap = 0
        if self.first < 0:
            self.first = index
        elif index > self.last + 1:
            gap = index - self.last - 1
            self.counters["gaps"] += 1
            self.counters["missed_samples"] += gap
        self.last = index
        return gap

    def observe(self, index: int) -> bool:
        """Sample ``index`` was received but skipped for a newer one; True if it is new.

        New: after the last sample taken or observed (taken later, it is in a gap).
        """
        if index <= max(self.last, self.observed):
            return False
        self.observed = int(index)
        return True

    def restart_at(self, first_index: int) -> None:
        """A new run of the loop: the next sample is ``first_index`` (no gap counted)."""
        self.last = self.observed = int(first_index) - 1


class GapReport:
    """The missing samples as events: at most one per ``period_samples`` samples.

    The first gap is reported at once; gaps within a period of the last report are summed
    into the next one (a controller falling behind would otherwise log a line per gap,
    costing the time it lacks).
    """

    def __init__(self, period_samples: int) -> None:
        """Nothing missing yet."""
        self.period_samples = int(period_samples)
        self._reported_at: int | None = None
        self._samples = 0
        self._gaps = 0

    def add(self, index: int, gap: int, events) -> None:
        """``gap`` samples missing before ``index``; report them (and those held) if due."""
        self._samples += gap
        self._gaps += 1
        if self._reported_at is not None and index - self._reported_at < self.period_samples:
            return
        text = (f"/pph/accel: {gap} samples missing before {index}" if self._gaps == 1 else
                f"/pph/accel: {self._samples} samples missing in {self._gaps} gaps, the last "
                f"before {index}")
        events.add("warn", text)
        self._reported_at, self._samples, self._gaps = index, 0, 0
