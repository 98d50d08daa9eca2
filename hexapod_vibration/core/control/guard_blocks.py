"""The divergence guard's input: the error cut into whole blocks, and each block's spectrum.

:class:`ErrorBlocks` buffers the DC-blocked error (m/s^2) one sample at a time and, at the end
of each block, gives the power of every FFT bin of the Hann-windowed block (channels summed)
with whether every sample of it was recording (control off, nothing injected) or judging
(control on). A block with samples missing (an index not after the last one's) is neither:
spliced, a residual sinusoid's jump is broadband power (2 samples missing from a 250-sample
block of a realtime run, 1.9 s after control-on: +23 dB in the 100 Hz third octave, and the
guard faded control out of a platform that was quieter than without it). A block with a
sample disturbed by a stand-in the driver reported (:mod:`~hexapod_vibration.core.control.
guard_feed`) is dropped the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ErrorBlock:
    """One whole block: its bin powers and what its samples were."""

    bins: np.ndarray
    """(F,) power of each bin ((m/s^2)^2, channels summed)."""
    recording: bool
    """Every sample was recording (may go into the reference)."""
    judging: bool
    """Every sample was judging (control on)."""


class ErrorBlocks:
    """The error (C channels) in blocks of ``block`` samples.

    Args:
        channels: number of error channels C.
        block: samples per block.
    """

    def __init__(self, channels: int, block: int) -> None:
        """Allocate the buffer; no sample yet."""
        self.block = int(block)
        self._buffer = np.zeros((self.block, int(channels)))
        self.window = np.hanning(self.block)[:, None]
        """The Hann window (block, 1) the spectra are taken with."""
        self._n = 0
        self._last_index = -1
        self._recording = self._judging = True
        self.with_gaps = 0
        """Blocks dropped (neither reference nor judged) for missing samples."""
        self.with_stand_ins = 0
        """Blocks dropped (neither reference nor judged) for a stand-in disturbed sample."""

    def add(self, error: np.ndarray, recording: bool, judging: bool,
            index: int | None = None, stood_in: bool = False) -> ErrorBlock | None:
        """Take sample ``index``'s error (C,) (None: the one after the last); a whole block.

        ``recording`` / ``judging``: what this sample is (see :class:`ErrorBlock`);
        ``stood_in``: a stand-in disturbed it (the block is dropped).
        """
        if self._n == 0:
            self._recording, self._judging = True, True
        elif index is not None and index != self._last_index + 1:
            if self._recording or self._judging:
                self.with_gaps += 1
            self._recording, self._judging = False, False
        if stood_in:
            if self._recording or self._judging:
                self.with_stand_ins += 1
            self._recording, self._judging = False, False
        if index is not None:
            self._last_index = index
        self._buffer[self._n] = error
        self._recording &= bool(recording)
        self._judging &= bool(judging)
        self._n += 1
        if self._n < self.block:
            return None
        self._n = 0
        spectrum = np.fft.rfft(self._buffer * self.window, axis=0)
        return ErrorBlock(np.sum(np.abs(spectrum) ** 2, axis=1), self._recording, self._judging)
