"""Which loop samples of a topic were seen already: a growing bit set over sample indices."""

from __future__ import annotations

SAMPLE_LOOKAHEAD = 10_000_000
"""A sample index this far beyond the highest seen (10 000 s at 1 kHz) is not a loop sample."""
GROWTH_BYTES = 4096
"""Bytes added beyond the needed ones when the set grows (32 768 samples)."""


class SampleSet:
    """The sample indices seen on one topic (one bit each)."""

    def __init__(self) -> None:
        """Nothing seen."""
        self._bits = bytearray()
        self.highest = -1
        """The highest sample index marked (-1: none)."""

    def add(self, sample: int) -> bool | None:
        """Mark ``sample`` (>= 0) seen; True if it was seen already.

        None (not marked) for an index so far ahead of the highest seen that it cannot be
        the loop's (:data:`SAMPLE_LOOKAHEAD`): the caller treats it as not a loop sample.
        """
        bits = self._bits
        byte, bit = divmod(sample, 8)
        if byte >= len(bits) + SAMPLE_LOOKAHEAD // 8:
            return None
        if byte >= len(bits):
            bits.extend(bytes(byte + 1 - len(bits) + GROWTH_BYTES))
        if bits[byte] >> bit & 1:
            return True
        bits[byte] |= 1 << bit
        if sample > self.highest:
            self.highest = sample
        return False
