"""Which received sample a controller acts on: run identity and index plausibility.

A controller answers the driver's samples one by one. Each sample carries its index ``n``
and the driver's run identity (``contract``: ``layout.dim[1]``, ``layout.dim[2]``). The rule
(docs/architecture.md, "Runs and restarts"):

- In the current run, the next sample is one with an index in (last, last + max_jump]:
  it is accepted; the indices skipped are reported as a gap (missing samples).
- The same index again is a repeat (the lockstep driver offers a sample again when it has
  not got every command for it): the controller re-sends its answer, it does not step.
- Anything else (another run, an index beyond last + max_jump, or a lower one: late)
  is dropped, and starts or continues a candidate sequence. That is adopted only after
  ``confirmations`` consecutive messages that continue it (same run, index not decreasing
  and within max_jump of the previous one); an accepted sample of the current run in
  between cancels it. So one bogus message (an absurd index, a stray run) changes nothing,
  a restarted driver (a new run from sample 0, offered again every 50 ms in lockstep) is
  followed within a few messages, and so is a publisher without runs that starts again
  from 0. Whatever took over (even a bogus sequence sent three times in a row while the
  loop was paused), the real stream takes it back in the same few messages.

The first message ever received is adopted at once (a controller started into a running
loop answers immediately).
"""

from __future__ import annotations

from enum import Enum
from typing import NamedTuple

MAX_JUMP_SAMPLES = 1000
"""Largest forward step (samples, 1 s at 1 kHz) accepted without confirmation."""

CONFIRMATIONS = 3
"""Consecutive consistent messages that make a candidate sequence the current one."""


class Admission(Enum):
    """What to do with a received sample."""

    ACCEPTED = "accepted"          # next sample of the current run: act on it
    NEW_RUN = "new_run"            # first sample of a newly adopted run (or of the same run
                                   # started again from a lower index): reset, then act
    REPEAT = "repeat"              # the last sample again: re-send the answer, do not act
    LATE = "late"                  # older than the last one: drop
    UNCONFIRMED = "unconfirmed"    # another run or an implausible jump, not yet confirmed


class Verdict(NamedTuple):
    """The admission of one sample, its index and the samples missing before it.

    A named tuple: one is made for every received sample (half the cost of a frozen
    dataclass).
    """

    admission: Admission
    index: int
    gap: int = 0

    @property
    def act(self) -> bool:
        """The controller acts on this sample (steps and answers)."""
        return self.admission in (Admission.ACCEPTED, Admission.NEW_RUN)


class SampleSequence:
    """The run and last sample index a controller follows (see the module docstring)."""

    def __init__(self, max_jump_samples: int = MAX_JUMP_SAMPLES,
                 confirmations: int = CONFIRMATIONS) -> None:
        """Empty sequence: the first message will be adopted.

        Args:
            max_jump_samples: Largest forward step accepted at once (samples, >= 1).
            confirmations: Messages that confirm a candidate sequence (>= 1).
        """
        if max_jump_samples < 1 or confirmations < 1:
            raise ValueError("max_jump_samples and confirmations must be >= 1")
        self.max_jump_samples = max_jump_samples
        self.confirmations = confirmations
        self.run: int | None = None
        self.last = -1
        self.started = False
        self.runs_adopted = 0
        self._candidate: tuple[int | None, int] | None = None
        self._candidate_count = 0

    def admit(self, index: int | None, run: int | None) -> Verdict:
        """Classify a received sample of index ``index`` (None: the next one) of ``run``."""
        if not self.started:
            return self._adopt(self.last + 1 if index is None else index, run)
        if run == self.run:
            if index is None:
                index = self.last + 1
            if self.last < index <= self.last + self.max_jump_samples:
                self._candidate = None
                gap, self.last = index - self.last - 1, index
                return Verdict(Admission.ACCEPTED, index, gap)
            if index == self.last:
                return Verdict(Admission.REPEAT, index)
        elif index is None:
            return Verdict(Admission.UNCONFIRMED, -1)
        return self._candidate_step(index, run)

    def _candidate_step(self, index: int, run: int | None) -> Verdict:
        """Continue or start the candidate sequence; adopt it once confirmed."""
        candidate = self._candidate
        if (candidate is not None and candidate[0] == run
                and candidate[1] <= index <= candidate[1] + self.max_jump_samples):
            self._candidate_count += 1
        else:
            self._candidate_count = 1
        self._candidate = (run, index)
        if self._candidate_count < self.confirmations:
            late = run == self.run and index < self.last
            return Verdict(Admission.LATE if late else Admission.UNCONFIRMED, index)
        if run == self.run and index > self.last:     # a confirmed jump within the run
            self._candidate = None
            gap, self.last = index - self.last - 1, index
            return Verdict(Admission.ACCEPTED, index, gap)
        return self._adopt(index, run)

    def _adopt(self, index: int, run: int | None) -> Verdict:
        self.started = True
        self.run, self.last = run, index
        self._candidate = None
        self.runs_adopted += 1
        return Verdict(Admission.NEW_RUN, index)
