"""A law's input across the samples its controller did not act on, so its state crosses a gap.

In realtime a controller can fall behind (its process descheduled): it then answers only the
newest samples queued (those the driver can still apply) and skips the older ones; samples
beyond its queue, or never delivered, are lost. A law with memory stepped once across such a
gap takes a gap's change as one sample's. The pointing law's rate is the difference of
consecutive eddy samples, and through its 15 Hz output low-pass a 10-sample stall (of a
40 Hz vibration) became a 2.3 N kick (realtime ``single_tone_harmonic``, measured by
replaying the law on the run's bag: 2.26 N at the largest of 39 gaps); the divergence guard
saw it as control making things worse and faded control out.

:class:`GapBridge` gives the law one input per sample from the last one it was given up to
the newest: a sample that was received (``skipped``: queued and skipped for a newer one) as
it is, a lost one as the continuation of the input's oscillation (per channel, from its last
``HISTORY_SAMPLES`` inputs, :class:`~hexapod_vibration.core.control.tone_continuation.
ToneContinuation`: one damped sinusoid, right for a signal with one dominant tone).

Measured by replaying the law on two realtime runs' bags (39 and 70 gaps of up to 10 and 21
samples; the kick of a gap: the largest change, over the 40 samples after it, of the
difference to the law that got every sample): stepped once, 2.26 / 12.8 N; with the 7
newest samples of each gap received (the law's queue is 10 deep, 3 answered) and the rest
continued, 0.011 / 1.46 N (a straight line instead of the continuation: 0.081 / 1.37 N);
with none received, continued, 0.069 / 4.6 N (a line: 0.85 / 3.7 N). On a simulated 40 Hz
vibration with gaps of 10 (``test/core/test_gap_bridge.py``): 2.04 N stepped once, 0.158 N
continued, 0.018 N with 7 of 10 received. In the node, the recorded pointing commands of
four realtime runs after the change are within 0.05 N of the law stepped on every recorded
eddy sample (2.28 N before).

A gap longer than ``MAX_BRIDGED_SAMPLES`` is not filled (its received samples are still
given): the continuation of a vibration that far ahead is no better than a step, and the law
should not spend the next samples' time catching up.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from hexapod_vibration.core.control.tone_continuation import ToneContinuation

MAX_BRIDGED_SAMPLES = 100
"""Longest gap (samples) whose lost samples are stood in for (0.1 s at 1 kHz)."""


class IndexedSample(Protocol):
    """A received sample: its index and values (``contract.StrutSample``)."""

    index: int | None
    values: np.ndarray


class GapBridge:
    """The inputs of a law with memory, one per sample, across the samples not acted on.

    Args:
        channels: Values per sample C.
    """

    def __init__(self, channels: int) -> None:
        """No sample yet."""
        self._channels = int(channels)
        self._history = ToneContinuation(self._channels)
        self._last = -1
        self.stood_in = 0
        """Lost samples stood in for by the continuation (since the start)."""

    def reset(self) -> None:
        """Forget the inputs (a new run: sample indices start again)."""
        self._history = ToneContinuation(self._channels)
        self._last = -1

    def inputs(self, index: int, values: np.ndarray,
               skipped: Sequence[IndexedSample] = ()) -> list[np.ndarray]:
        """The inputs ((C,) each) for the samples after the last one given, up to ``index``.

        Oldest first; the last is ``values`` (sample ``index``). Before it: the ``skipped``
        samples between (received, not acted on) and, for a gap of at most
        ``MAX_BRIDGED_SAMPLES``, stand-ins for the lost ones. A first sample, or one not
        after the last, gives ``[values]``.
        """
        last, self._last = self._last, int(index)
        gap = index - last - 1
        if last < 0 or gap <= 0:
            self._history.add(values)
            return [values]
        received = {s.index: s.values for s in skipped if s.index is not None
                    and last < s.index < index}
        if gap > MAX_BRIDGED_SAMPLES:
            self._history = ToneContinuation(self._channels)     # too old to continue
            out = [received[i] for i in sorted(received)] + [values]
            for row in out[:-1]:
                self._history.add(row)
        else:
            out = self._bridged(last, index, received) + [values]
        self._history.add(values)
        return out

    def _bridged(self, last: int, index: int, received: dict) -> list[np.ndarray]:
        """Inputs for samples ``last + 1 .. index - 1``: received ones, else continued."""
        out: list[np.ndarray] = []
        sample = last + 1
        while sample < index:
            if sample in received:
                rows = [received[sample]]
            else:
                lost = sample
                while lost < index and lost not in received:
                    lost += 1
                rows = list(self._history.forecast(lost - sample))
                self.stood_in += len(rows)
            for row in rows:
                self._history.add(row)
            out.extend(rows)
            sample += len(rows)
        return out
