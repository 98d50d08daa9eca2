"""Per-sample digital filters for the 1 kHz control path (vectorized over channels).

scipy.signal designs the filters; these classes only run them one sample at a time, which
``scipy.signal.sosfilt`` cannot do cheaply (its per-call overhead is ~100 us).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from hexapod_vibration.core.model.kernel_choice import compiled_law_kernels

# Bound once: at six channels the per-sample methods cost mostly numpy call overhead, so
# they use preallocated arrays and ufuncs with positional outputs.
_add, _multiply, _subtract = np.add, np.multiply, np.subtract


class SosFilterBank:
    """Second-order sections applied sample by sample to ``channels`` signals.

    Transposed direct form II, the same operations in the same order as ``sosfilt``;
    state (sections, 2, channels), like ``sosfilt``'s ``zi``. Where the compiled kernels are
    in use (``compiled``, :func:`~hexapod_vibration.core.model.kernel_choice.
    compiled_law_kernels`) one call steps every section, with the same numbers.
    """

    def __init__(self, sos: np.ndarray, channels: int) -> None:
        """Run the sections ``sos`` (from ``scipy.signal``, output='sos') on each channel."""
        self.sos = np.ascontiguousarray(sos, dtype=float)
        self.channels = channels
        self.compiled = compiled_law_kernels()
        """The compiled kernels that step the bank, or None (NumPy, per section)."""
        self.state = np.zeros((self.sos.shape[0], 2, channels))
        """The sections' z0, z1 (sections, 2, channels) while ``compiled`` steps the bank."""
        self._sections = [_Section(coefficients, channels) for coefficients in self.sos]

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
        zi = signal.sosfilt_zi(self.sos)[:, :, None] * level
        if self.compiled is not None:
            self.state[...] = zi
            return
        for section, states in zip(self._sections, zi, strict=True):
            section.states[...] = states

    def step(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (channels,); returns a new array."""
        if self.compiled is not None:
            y = np.array(np.broadcast_to(x, (self.channels,)), dtype=float)
            self.compiled.sos_into(self.sos, self.state, y, y)
            return y
        y = np.asarray(x, float)
        for section in self._sections:
            y = section.step(y)
        return y


class _WorkRows:
    """The (3, channels) work array of a section and views of its rows."""

    def __init__(self, channels: int) -> None:
        self.array = np.zeros((3, channels))
        self.direct = self.array[0]                 # b0 u
        self.z0, self.z1 = self.array[1], self.array[2]
        self.states = self.array[1:]


class _Section:
    """One second-order section on all channels, with ``sosfilt``'s arithmetic.

    Per sample, input u: ``y = b0 u + z0``, ``z0' = b1 u - a1 y + z1``, ``z1' = b2 u - a2 y``.
    Two work arrays take turns: the new one receives b0 u, b1 u, b2 u and then the next
    states (rows 1, 2); the current one holds the present states there.
    """

    def __init__(self, coefficients: np.ndarray, channels: int) -> None:
        """Coefficients ``[b0, b1, b2, 1, a1, a2]`` of the section."""
        self._b = np.repeat(coefficients[0:3, None], channels, axis=1)    # rows b0, b1, b2
        self._a = np.repeat(coefficients[4:6, None], channels, axis=1)    # rows a1, a2
        self._feedback = np.zeros((2, channels))                          # a1 y, a2 y
        self._work = (_WorkRows(channels), _WorkRows(channels))           # (current, next)

    @property
    def states(self) -> np.ndarray:
        """The present states z0, z1 (2, channels): a view, writable."""
        return self._work[0].states

    def step(self, u: np.ndarray) -> np.ndarray:
        """One sample u (channels,) -> y, a new array."""
        now, new = self._work
        _multiply(self._b, u, new.array)
        y = _add(new.direct, now.z0)
        _multiply(self._a, y, self._feedback)
        _subtract(new.states, self._feedback, new.states)
        _add(new.z0, now.z1, new.z0)
        self._work = (new, now)
        return y


class DCBlocker:
    """First-order DC blocker ``y[n] = x[n] - x[n-1] + r y[n-1]`` per channel.

    ``r = exp(-2 pi f_c / fs)`` gives a -3 dB corner near ``cutoff_hz``; at 40 Hz with the
    default 0.5 Hz corner the gain is 0.9999 and the phase lead 0.7 deg (the identification
    of the plant includes it). The first sample initialises the state, so a constant input
    gives exactly zero output from the start. ``r`` (-) is fixed at construction.
    """

    def __init__(self, channels: int, sample_rate_hz: float, cutoff_hz: float = 0.5) -> None:
        """Create the filter for ``channels`` signals sampled at ``sample_rate_hz``."""
        if not 0.0 < cutoff_hz < sample_rate_hz / 2.0:
            raise ValueError(f"DC-blocker cutoff must be in (0, fs/2) Hz, got {cutoff_hz}")
        self.r = float(np.exp(-2.0 * np.pi * cutoff_hz / sample_rate_hz))
        self._r_channels = np.full(channels, self.r)    # array * array is cheaper
        self._x_prev = np.zeros(channels)
        self._feedback = np.zeros(channels)             # r y[n-1]
        self._primed = False

    def step(self, x: np.ndarray) -> np.ndarray:
        """Filter one sample (channels,) and return the DC-free value (a new array)."""
        if not self._primed:
            self._x_prev[...] = x
            self._primed = True
        y = _subtract(x, self._x_prev)
        _add(y, self._feedback, y)
        _multiply(self._r_channels, y, self._feedback)
        self._x_prev[...] = x
        return y

    def reset(self) -> None:
        """Forget the state; the next sample re-initialises it."""
        self._primed = False
        self._feedback[...] = 0.0
