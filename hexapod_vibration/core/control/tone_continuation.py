"""A controller's next commands, continuing the oscillation of its last ones (per strut).

The pointing controller's forecast for a realtime driver (``/pph/pointing_forecast``). Its
command is a low-passed PID of the eddy sensors, and while the shaker runs its largest part
is the platform's vibration at the shaker's tone (86 % of its power in 35-45 Hz during a
realtime identification, rms 1.1 N per strut). Held, a late command of such a signal is off
by about its rms after a few samples: an input error at the tone, which spoiled realtime
identifications (22 % uncertainty in a run with 102 held samples).

:class:`ToneContinuation` keeps the last ``HISTORY_SAMPLES`` commands (of every sample: the
controller steps its law through those it skipped, :mod:`~hexapod_vibration.core.control.
gap_bridge`), fits per strut a second-order autoregression
of the commands less their mean (the normal equations, every strut at once: one damped
sinusoid) and continues it from the last two commands, around the mean. A strut whose fit is
not an oscillation, or before the history is full, holds its last command; the pole radius
is kept below ``MAX_POLE_RADIUS``, so a forecast never grows. A fourth-order model through
``scipy.signal.lfilter`` predicted better (a third of the hold's error against about half)
but cost 0.35 ms per forecast against 0.17 ms (measured then; the second-order forecast of
200 samples now takes 71 us warm against 113 before: the normal equations from one batched
product, the pole's powers by a running product; where numba is installed one compiled call,
:mod:`~hexapod_vibration.core.control.compiled_continuation`, 7 us warm, 14 us cold). On the
pointing commands of a realtime run (every 10th sample, 50 ahead): rms error 0.03 / 0.14 /
0.49 N at 1 / 5 / 20 samples ahead against 0.17 / 0.53 / 1.08 N for the hold.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.model.kernel_choice import compiled_continuation_kernels

HISTORY_SAMPLES = 200
"""Commands the model is fitted to (0.2 s at 1 kHz: eight periods of 40 Hz)."""
MAX_POLE_RADIUS = 0.999
"""Largest radius of the continued oscillation's pole (-18 % over 200 samples)."""


class ToneContinuation:
    """The last commands (N) of a controller and their continuation.

    Args:
        channels: Commands per sample C (six struts).
    """

    def __init__(self, channels: int) -> None:
        """An empty history."""
        self._ring = np.zeros((HISTORY_SAMPLES, int(channels)))
        self._next = 0
        self._filled = 0
        self.compiled = compiled_continuation_kernels()
        """The compiled kernel that forecasts, or None (NumPy, the same numbers to 1e-9 N)."""

    def add(self, command: np.ndarray) -> None:
        """The controller's command (N, (C,)) of its latest sample."""
        self._ring[self._next] = command
        self._next = (self._next + 1) % HISTORY_SAMPLES
        self._filled = min(self._filled + 1, HISTORY_SAMPLES)

    def forecast(self, samples: int) -> np.ndarray:
        """The next ``samples`` commands (N, (samples, C)) after the last one added."""
        rows = np.empty((int(samples), self._ring.shape[1]))
        if self._filled == HISTORY_SAMPLES and self.compiled is not None:
            self.compiled.continue_tone(self._ring, self._next, MAX_POLE_RADIUS, rows)
            return rows
        rows[:] = self._ring[self._next - 1]                         # held
        if self._filled < HISTORY_SAMPLES:
            return rows
        a1, a2, mean, y = self._fit()
        discriminant = a1 * a1 + 4.0 * a2             # z^2 - a1 z - a2: complex poles if < 0
        oscillates = np.isfinite(discriminant) & (discriminant < 0.0)
        if not oscillates.any():
            return rows
        a1, a2 = a1[oscillates], np.abs(a2[oscillates])
        radius = np.minimum(np.sqrt(a2), MAX_POLE_RADIUS)
        pole = radius * np.exp(1j * np.arccos(np.clip(a1 / (2.0 * np.sqrt(a2)), -1.0, 1.0)))
        y0, y_1 = y[oscillates, -1], y[oscillates, -2]
        # y[k] = Re(c p^k): Re(c) = y0, Re(c / p) = y_1
        imag = (y_1 * radius**2 - y0 * pole.real) / pole.imag
        powers = np.cumprod(np.broadcast_to(pole, (int(samples), pole.size)), axis=0)  # p^k
        rows[:, oscillates] = mean[oscillates] + ((y0 + 1j * imag) * powers).real
        return rows

    def _fit(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per strut a1, a2 of y[k] = a1 y[k-1] + a2 y[k-2] (NaN: no fit), mean, y (C, T).

        The normal equations of every strut from one batched product of its lagged series.
        """
        nxt = self._next
        history = np.concatenate((self._ring[nxt:], self._ring[:nxt]))     # oldest first
        mean = history.sum(0) * (1.0 / HISTORY_SAMPLES)
        y = np.ascontiguousarray((history - mean).T)
        lags = np.stack((y[:, 1:-1], y[:, :-2], y[:, 2:]), axis=1)   # past1, past2, now
        gram = lags @ lags.transpose(0, 2, 1)                         # (C, 3, 3)
        g11, g12, g22 = gram[:, 0, 0], gram[:, 0, 1], gram[:, 1, 1]
        b1, b2 = gram[:, 0, 2], gram[:, 1, 2]
        det = g11 * g22 - g12 * g12
        with np.errstate(divide="ignore", invalid="ignore"):
            a1 = (b1 * g22 - b2 * g12) / det
            a2 = (g11 * b2 - g12 * b1) / det
        singular = ~(det > 0.0)
        a1[singular] = np.nan
        return a1, a2, mean, y
