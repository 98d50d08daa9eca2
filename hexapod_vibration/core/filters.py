"""Per-sample digital filters for the 1 kHz control path (vectorized over channels).

scipy.signal designs the filters; these classes only run them one sample at a time, which
``scipy.signal.sosfilt`` cannot do cheaply (its per-call overhead is ~100 us).
"""

from __future__ import annotations

import numpy as np
from scipy import signal


class SosFilterBank:
    """Second-order sections applied sample by sample to ``channels`` signals.

    Transposed direct form II, state (sections, 2, channels), like ``sosfilt``'s ``zi``.
    """

    def __init__(self, sos: np.ndarray, channels: int) -> None:
        """Run the sections ``sos`` (from ``scipy.signal``, output='sos') on each channel."""
        self.sos = np.asarray(sos, float)
        self.channels = channels
        self._zi = np.zeros((self.sos.shape[0], 2, channels))

    @classmethod
    def butter_lowpass(cls, order: int, cutoff_hz: float, sample_rate_hz: float,
                       channels: int) -> SosFilterBank:
        """Butterworth low-pass of ``order`` with its -3 dB corner at ``cutoff_hz``."""
        if not 0.0 < cutoff_hz < sample_rate_hz / 2.0:
            raise ValueError(f"low-pass corner must be in (0, fs/2) Hz, got {cutoff_hz}")
        return cls(signal.butter(order, cutoff_hz, fs=sample_rate_hz, output="sos"), channels)

    def reset(self, value: np.ndarray | float = 0.0) -> None:
        """Steady state for a constant input ``value`` (per channel)."""
        level = np.broadcast_to(np.asarray(value, float), (self.channels,))
        self._zi = signal.sosfilt_zi(self.sos)[:, :, None] * level

    def step(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (channels,)."""
        y = np.asarray(x, float)
        for s, zi in zip(self.sos, self._zi, strict=True):
            out = s[0] * y + zi[0]
            zi[0] = s[1] * y - s[4] * out + zi[1]
            zi[1] = s[2] * y - s[5] * out
            y = out
        return y


class DCBlocker:
    """First-order DC blocker ``y[n] = x[n] - x[n-1] + r y[n-1]`` per channel.

    ``r = exp(-2 pi f_c / fs)`` gives a -3 dB corner near ``cutoff_hz``; at 40 Hz with the
    default 0.5 Hz corner the gain is 0.9999 and the phase lead 0.7 deg (the identification
    of the plant includes it). The first sample initialises the state, so a constant input
    gives exactly zero output from the start.
    """

    def __init__(self, channels: int, sample_rate_hz: float, cutoff_hz: float = 0.5) -> None:
        """Create the filter for ``channels`` signals sampled at ``sample_rate_hz``."""
        if not 0.0 < cutoff_hz < sample_rate_hz / 2.0:
            raise ValueError(f"DC-blocker cutoff must be in (0, fs/2) Hz, got {cutoff_hz}")
        self.r = float(np.exp(-2.0 * np.pi * cutoff_hz / sample_rate_hz))
        self._x_prev = np.zeros(channels)
        self._y_prev = np.zeros(channels)
        self._primed = False

    def step(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (channels,) and return the DC-free value."""
        if not self._primed:
            self._x_prev[:] = x
            self._primed = True
        y = x - self._x_prev + self.r * self._y_prev
        self._x_prev[:] = x
        self._y_prev[:] = y
        return y

    def reset(self) -> None:
        """Forget the state; the next sample re-initialises it."""
        self._primed = False
        self._y_prev[:] = 0.0
