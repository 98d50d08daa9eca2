"""Where each tone's line really is, read off the turning of the canceller's weights.

A canceller whose oscillator runs ``df`` Hz off the disturbance line it cancels has weights
that turn at ``2 pi df`` rad/s once they follow the line (paper eq. 21): the weights are the
line's phasor seen from the oscillator. :class:`LineOffsetMonitor` measures that turning
without acting on it (a fixed-frequency canceller, ``frequency_tracking`` off): every
``block_samples`` samples it takes, per tone, the block's mean weights and
``z = sum_c w_c conj(w_c, previous block)`` (the turning of the weight vector over a block,
weighted by its size), and averages ``z`` and ``|z|`` exponentially over
``time_constant_s``. (The mean, not one sample: the weights ripple at about twice the tone,
and 40 Hz's ripple seen every 50 ms aliases to a few hundredths of a hertz of turning.) Then

- ``offset_hz = angle(mean z) / (2 pi block / fs)``: the line's offset from the oscillator
  (Hz, + above it), unambiguous within +-fs / (2 block) (+-10 Hz at 50 samples);
- ``coherence = |mean z| / mean |z|`` (0..1): 1 for weights that turn steadily, small for
  weights that wander (a tone with no line under it: noise-driven weights turn one way
  and the other, at rates within the notch's own width).

The supervisor compares the predicted reduction of the line at ``tone + offset_hz`` with the
guard's margin (:meth:`NotchSupervisor._line_offset_step`). Pure numpy; no ROS.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

DEFAULT_BLOCK_SAMPLES = 50
DEFAULT_TIME_CONSTANT_S = 0.5
MIN_COHERENCE = 0.8
"""Coherence from which an offset counts as a measurement (a steadily turning line)."""


class LineOffsetMonitor:
    """The offset (Hz) of each tone's line from its oscillator, from the weights' turning.

    Args:
        tones: number of tones T.
        sample_rate_hz: loop rate fs (Hz).
        block_samples: samples between two looks at the weights.
        time_constant_s: averaging time constant of the turning (s).
    """

    def __init__(self, tones: int, sample_rate_hz: float,
                 block_samples: int = DEFAULT_BLOCK_SAMPLES,
                 time_constant_s: float = DEFAULT_TIME_CONSTANT_S) -> None:
        """No measurement until :meth:`ready`."""
        if block_samples < 1 or not time_constant_s > 0.0:
            raise ValueError(f"block_samples must be >= 1 and time_constant_s > 0, got "
                             f"{block_samples!r}, {time_constant_s!r}")
        self.fs = float(sample_rate_hz)
        self.block = int(block_samples)
        self.block_s = self.block / self.fs
        self._alpha = 1.0 - np.exp(-self.block_s / time_constant_s)
        self._settle_blocks = int(np.ceil(2.0 * time_constant_s / self.block_s))
        self.tones = int(tones)
        self.reset()

    def reset(self) -> None:
        """Forget the weights seen (control starts again, new tones)."""
        self._count = 0
        self._blocks = 0
        self._sum_h: np.ndarray | None = None      # sum of conj(W).T over the block, (C, T)
        self._previous: np.ndarray | None = None
        self._z = np.zeros(self.tones, dtype=complex)
        self._magnitude = np.zeros(self.tones)

    def step(self, weights: np.ndarray) -> bool:
        """Take this sample's complex (T, C) weights (N); True when a block was looked at."""
        weights = np.asarray(weights)
        total = self._block_sum(weights.shape[1])
        np.add(total, np.conj(weights).T, out=total)
        return self._counted()

    def step_from(self, canceller: AdaptiveNotchCanceller) -> bool:
        """:meth:`step` on the canceller's adapted weights, added in place (no copy)."""
        canceller.add_adapted_weights_h(self._block_sum(canceller.n_channels))
        return self._counted()

    def _block_sum(self, channels: int) -> np.ndarray:
        """The block's running sum (C, T), zeroed at the block's first sample."""
        if self._sum_h is None or self._sum_h.shape != (channels, self.tones):
            self._sum_h = np.zeros((channels, self.tones), dtype=complex)
        elif self._count == 0:
            self._sum_h.fill(0.0)
        return self._sum_h

    def _counted(self) -> bool:
        """Count the sample; at a block's end, take the turning since the last block."""
        self._count += 1
        if self._count < self.block:
            return False
        self._count = 0
        w = np.conj(self._sum_h).T / self.block
        if self._previous is not None and self._previous.shape == w.shape:
            z = np.sum(w * np.conj(self._previous), axis=1)
            self._z += self._alpha * (z - self._z)
            self._magnitude += self._alpha * (np.abs(z) - self._magnitude)
            self._blocks += 1
        self._previous = w
        return True

    @property
    def started(self) -> bool:
        """True once a sample was taken since the last :meth:`reset`."""
        return self._count > 0 or self._previous is not None

    @property
    def ready(self) -> bool:
        """True once two time constants of blocks were averaged."""
        return self._blocks >= self._settle_blocks

    @property
    def offset_hz(self) -> np.ndarray:
        """(T,) the lines' offsets from the oscillators (Hz, + above)."""
        return np.angle(self._z) / (2.0 * np.pi * self.block_s)

    @property
    def coherence(self) -> np.ndarray:
        """(T,) how steadily the weights turn (0..1)."""
        return np.abs(self._z) / np.maximum(self._magnitude, 1e-300)
