"""Compiled (numba) per-sample arithmetic of the pointing law, bit for bit the NumPy one.

One 1 kHz sample of :class:`~hexapod_vibration.core.control.pointing.PointingController` is
about 20 small NumPy calls (the inputs' update, the law's product, the anti-windup test, two
Butterworth sections on six forces, the saturation): ~7 us warm, several times that in the
pointing controller's process, where the caches are cold. Removing the law from the loop
altogether (an upper bound: a scratch tree whose law returned its last force) ran the Table 1
graph through separate processes 1.73 -> 1.85x real time (4 interleaved pairs). These kernels
do the same arithmetic in one call.

Bit for bit, as :mod:`~hexapod_vibration.core.model.compiled_sample`: every element-wise
operation is NumPy's, in the same order, in IEEE double (no ``fastmath``: no reassociation,
no fused multiply-add); the law's product goes through ``np.dot`` (BLAS gemv, as NumPy's
``matmul`` of a matrix and a vector). test/core/test_pointing.py checks the compiled law's
forces and integral against the NumPy law's for equality, and both against the documented
reference; test_filters.py the filter bank on both paths against ``sosfilt``.

No kernel returns an array (see ``compiled_sample``): they write into the caller's buffers.
numba is optional: :func:`~hexapod_vibration.core.model.kernel_choice.compiled_law_kernels`
imports this module on first use.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_F1 = numba.float64[::1]
_F2 = numba.float64[:, ::1]
_F3 = numba.float64[:, :, ::1]


@numba.njit(cache=True)
def _sections(sos: np.ndarray, state: np.ndarray, x: np.ndarray, first: int,
              y: np.ndarray) -> None:
    """The sections ``sos`` (S, 6) on ``x[first:first + C]`` into ``y`` (C,): :func:`sos_into`."""
    for i in range(y.size):
        y[i] = x[first + i]
    for s in range(sos.shape[0]):
        b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
        for i in range(y.size):
            u = y[i]
            out = b0 * u + state[s, 0, i]
            z0 = b1 * u - a1 * out
            state[s, 0, i] = z0 + state[s, 1, i]
            state[s, 1, i] = b2 * u - a2 * out
            y[i] = out


@numba.njit((_F2, _F3, _F1, _F1), cache=True)
def sos_into(sos: np.ndarray, state: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """``SosFilterBank.step``: the sections ``sos`` (S, 6) on ``x`` (C,), into ``y`` (C,).

    ``state`` (S, 2, C) holds each section's z0, z1 (transposed direct form II, ``sosfilt``'s
    arithmetic: ``y = b0 u + z0``, ``z0' = (b1 u - a1 y) + z1``, ``z1' = b2 u - a2 y``).
    ``x`` and ``y`` may be the same array.
    """
    _sections(sos, state, x, 0, y)


@numba.njit((_F2, _F1, _F1, _F1, _F1, numba.boolean, numba.float64, _F2, _F3, _F1),
            cache=True)
def pointing_step(law: np.ndarray, inputs: np.ndarray, terms: np.ndarray, gaps_m: np.ndarray,
                  target: np.ndarray, primed: bool, limit_n: float, sos: np.ndarray,
                  state: np.ndarray, force_n: np.ndarray) -> None:
    """``PointingController.step``: the strut forces (N) of one sample into ``force_n``.

    ``inputs`` (4C,) are the law's stacked inputs [gaps, gap change, target, integral] and
    ``terms`` (4C,) its outputs [candidate integral, its forces, forces, forces with the
    integral held] (``PointingController._law_matrix``); ``primed``: a previous sample's
    gaps are in ``inputs`` (else the gap change is zero). The output low-pass is ``sos`` on
    ``state`` (:func:`sos_into`), then each force is saturated at +-``limit_n`` (NaN passes,
    as through ``np.minimum``).
    """
    c = gaps_m.size
    for i in range(c):
        inputs[c + i] = gaps_m[i] - inputs[i] if primed else 0.0
        inputs[i] = gaps_m[i]
        inputs[2 * c + i] = target[i]
    terms[:] = np.dot(law, inputs)
    peak, total = 0.0, 0.0
    for i in range(c):            # _exceeds: max |force| > limit, False if one is NaN
        magnitude = abs(terms[c + i])
        total += magnitude
        peak = max(peak, magnitude)
    held = peak > limit_n and not math.isnan(total)
    if not held:
        for i in range(c):
            inputs[3 * c + i] = terms[i]
    _sections(sos, state, terms, 3 * c if held else 2 * c, force_n)
    for i in range(c):
        f = force_n[i]
        if f > limit_n:           # comparisons, not min/max: NaN passes
            f = limit_n
        if f < -limit_n:
            f = -limit_n
        force_n[i] = f
