"""The divergence guard's bands: which FFT bins of a block make each band it judges.

For a tone set, the bands of :class:`~hexapod_vibration.core.control.divergence_guard.
DivergenceGuard` are, in this order: one per tone (``f_t +- half_width_hz``), the broadband
(``BROADBAND_LOW_HZ`` .. fs/2), and every one-third octave from ``THIRD_OCTAVE_LOW_HZ`` to
fs/2 that keeps at least three bins once the bins within a tone's band or its window's main
lobe are left out (a converging tone is no rise). :class:`GuardBands` holds the masks of one
tone set and gives those of tones that moved (tracking, a tachometer).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.spectrum import third_octave_bands_hz

BROADBAND_LOW_HZ = 8.0
"""Below this (two 4 Hz bins) the DC blocker's settling leaks into the block's spectrum:
left out of the broadband."""
THIRD_OCTAVE_LOW_HZ = 50.0
MIN_OCTAVE_BINS = 3
"""A third octave with fewer bins off the tones is not a band (its noise would judge)."""


class GuardBands:
    """(B, F) bin masks of the tones' bands, the broadband and the third octaves.

    Args:
        block: samples per block (its FFT has ``block // 2 + 1`` bins).
        sample_rate_hz: loop rate fs (Hz).
        half_width_hz: half width of each tone's band (Hz).
        tone_frequencies_hz: the tones (Hz) the third octaves are chosen around.
    """

    def __init__(self, block: int, sample_rate_hz: float, half_width_hz: float,
                 tone_frequencies_hz: Sequence[float]) -> None:
        """The bands of ``tone_frequencies_hz``."""
        self.freqs = np.fft.rfftfreq(block, 1.0 / sample_rate_hz)
        self.half_width_hz = float(half_width_hz)
        self._lobe_hz = self.half_width_hz + 2.0 * sample_rate_hz / block
        tones = np.asarray(tone_frequencies_hz, dtype=float)
        near_tone = self._near(tones)
        self.octaves = [(centre, lo, hi) for centre, lo, hi
                        in third_octave_bands_hz(THIRD_OCTAVE_LOW_HZ, 0.5 * sample_rate_hz)
                        if np.count_nonzero(self._octave(lo, hi, near_tone)) >= MIN_OCTAVE_BINS]
        self.masks, _ = self.masks_for(tones)
        self.names = ([f"tone {f:g} Hz" for f in tones] + ["broadband"]
                      + [f"1/3 octave {c:.0f} Hz" for c, _, _ in self.octaves])
        self.main = tones.size + 1
        """The tones' bands and the broadband come first: ``masks[:main]``."""

    def masks_for(self, tones: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, F) masks of the bands around ``tones`` (Hz); (B,) usable.

        The third octaves (those chosen at construction) leave out the bins within the
        tones' bands and their window's main lobe; one left with fewer than
        ``MIN_OCTAVE_BINS`` bins is not usable.
        """
        near_tone = self._near(tones)
        out = np.vstack([self.tone_masks(tones), self.freqs >= BROADBAND_LOW_HZ,
                         *(self._octave(lo, hi, near_tone) for _, lo, hi in self.octaves)]
                        ).astype(float)
        usable = np.ones(out.shape[0], bool)
        usable[tones.size + 1:] = out[tones.size + 1:].sum(axis=1) >= MIN_OCTAVE_BINS
        return out, usable

    def tone_masks(self, tones: np.ndarray) -> np.ndarray:
        """(T, F) float masks of the bands around ``tones`` (Hz)."""
        return (np.abs(self.freqs[None, :] - np.asarray(tones)[:, None])
                <= self.half_width_hz).astype(float)

    def _octave(self, lo: float, hi: float, near_tone: np.ndarray) -> np.ndarray:
        """(F,) bins of the third octave ``lo`` .. ``hi`` (Hz) off the tones."""
        return (self.freqs >= lo) & (self.freqs < hi) & ~near_tone

    def _near(self, tones: np.ndarray) -> np.ndarray:
        """(F,) bins within a tone's band or its window's main lobe."""
        if not len(tones):
            return np.zeros(self.freqs.size, bool)
        return np.any(np.abs(self.freqs[None, :] - np.asarray(tones)[:, None])
                      <= self._lobe_hz, axis=0)
