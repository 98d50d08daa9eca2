"""Compiled (numba) :meth:`ToneContinuation.forecast`: the fit and the continuation in one call.

:class:`~hexapod_vibration.core.control.tone_continuation.ToneContinuation`'s NumPy forecast
is ~20 array operations on (200, 6) real and complex arrays: 71 us warm, 145 us with the
caches evicted, and 268 us (median) in the pointing controller's process of a realtime
graph, every 10 samples (``docs/performance.md``). This kernel does the same arithmetic
strut by strut in plain loops, without a temporary array: 7.3 us warm, 13.8 us cold.

Not bit for bit: the NumPy fit sums its normal equations in a BLAS product and its mean
pairwise; here the sums run in order. test/core/test_tone_continuation.py checks both paths
against a second method (per-strut least squares and the recurrence, 1e-9 N) and against
each other. numba is optional: :func:`~hexapod_vibration.core.model.kernel_choice.
compiled_continuation_kernels` imports this module on first use.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def _continue_strut(ring: np.ndarray, next_row: int, c: int, max_radius: float,
                    rows: np.ndarray) -> bool:
    """Strut ``c`` of :func:`continue_tone` if its fit oscillates; False (rows untouched) if not."""
    history = ring.shape[0]
    total = 0.0
    for k in range(history):
        total += ring[k, c]
    mean = total * (1.0 / history)
    g11 = g12 = g22 = b1 = b2 = 0.0
    before2 = ring[next_row % history, c] - mean                # y[k-2], oldest first
    before1 = ring[(next_row + 1) % history, c] - mean          # y[k-1]
    for k in range(2, history):
        now = ring[(next_row + k) % history, c] - mean
        g11 += before1 * before1
        g12 += before1 * before2
        g22 += before2 * before2
        b1 += before1 * now
        b2 += before2 * now
        before2, before1 = before1, now
    det = g11 * g22 - g12 * g12
    if not det > 0.0:
        return False
    a1 = (b1 * g22 - b2 * g12) / det
    a2 = (g11 * b2 - g12 * b1) / det
    discriminant = a1 * a1 + 4.0 * a2                       # z^2 - a1 z - a2: complex if < 0
    if not (math.isfinite(discriminant) and discriminant < 0.0):
        return False
    a2 = abs(a2)
    radius = min(math.sqrt(a2), max_radius)
    angle = math.acos(min(max(a1 / (2.0 * math.sqrt(a2)), -1.0), 1.0))
    pole = radius * complex(math.cos(angle), math.sin(angle))
    y0, y_1 = before1, before2                                  # the last two, about the mean
    imag = (y_1 * radius * radius - y0 * pole.real) / pole.imag  # Re(c) = y0, Re(c / p) = y_1
    amplitude = complex(y0, imag)
    power = pole
    for k in range(rows.shape[0]):
        rows[k, c] = mean + (amplitude * power).real
        power *= pole
    return True


@numba.njit((numba.float64[:, ::1], numba.int64, numba.float64, numba.float64[:, ::1]),
            cache=True)
def continue_tone(ring: np.ndarray, next_row: int, max_radius: float,
                  rows: np.ndarray) -> None:
    """The full history ``ring`` (T, C) continued into ``rows`` (K, C), N.

    ``ring`` is circular, its oldest row at ``next_row``. Per strut: the mean, the
    second-order autoregression of the rest by its normal equations, and, where its poles
    are complex, the damped sinusoid through the last two values with the pole's radius
    at most ``max_radius``; else (or a singular fit) the last value held.
    """
    history, strut_count = ring.shape
    for c in range(strut_count):
        if not _continue_strut(ring, next_row, c, max_radius, rows):
            last = ring[(next_row - 1) % history, c]
            for k in range(rows.shape[0]):
                rows[k, c] = last

