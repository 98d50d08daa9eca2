"""Compiled (numba) per-sample arithmetic of the simulated hexapod, bit for bit the NumPy one.

One 1 kHz sample of :class:`~hexapod_vibration.core.model.plant.PPHPlant` is about 45 small
NumPy calls (the shaker's tones, the held voice-coil force, the lifted product and its
regime test, the accelerometers' filter, noise, clipping and quantisation), each with a fixed
interpreter cost: ~30 us warm, and ~100 us in the driver's process, where the caches are cold
(measured by replaying recorded samples instead of stepping: the composed lockstep ran 3.3x
then 4.9x real time). These kernels do the same arithmetic in four calls.

Bit for bit: every element-wise operation is the NumPy one, in the same order, in IEEE double
(no ``fastmath``, so no reassociation or fused multiply-add); the products go through
``np.dot``, which numba hands to BLAS (SciPy's OpenBLAS; NumPy calls its own OpenBLAS with the
same routines, gemv and gemm, for these shapes), and ``np.sin`` gives NumPy's values. The
random draws stay NumPy's (the caller draws them), so the noise streams are the same.
test/core/test_compiled_sample.py checks a compiled plant's samples, counters and noise
streams against the NumPy plant's for equality, test_plant_speed_equivalence.py both paths
against a plain reference.

numba is optional: :func:`~hexapod_vibration.core.model.kernel_choice.compiled_kernels`
imports this module on first use (see there). The kernels are compiled for their one signature
when it is imported, from numba's on-disk cache after the first time.

No kernel returns an array: a returned array is boxed by Python code (numba's
``_numba_unpickle``) that runs inside the call, where a signal handler raising an exception
(the nodes' Ctrl-C, ``cli.StopSignal``) turned into a ``SystemError``. They write into
the caller's buffers and return numbers; ``test_compiled_sample.py`` checks that a plant
step runs no Python code inside a kernel.
"""

from __future__ import annotations

import numba
import numpy as np

_F1 = numba.float64[::1]
_F2 = numba.float64[:, ::1]


@numba.njit((_F2, _F2, _F2, _F2, _F1, numba.float64, _F1, numba.float64, _F1), cache=True)
def shaker_tones_into(offsets_s: np.ndarray, w_rad_s: np.ndarray, phase_rad: np.ndarray,
                      scratch: np.ndarray, amplitude_n: np.ndarray, start_s: float,
                      noise_n: np.ndarray, limit_n: float, out: np.ndarray) -> None:
    """``Shaker._tone_sum`` then ``_add_noise_and_limit`` (N), into ``out``.

    ``noise_n`` holds the draws of this sample (empty: no noise). The grids are the
    shaker's (time offset, angular frequency and phase per internal step and tone).
    """
    for k in range(scratch.shape[0]):
        for t in range(scratch.shape[1]):
            s = offsets_s[k, t] + start_s
            s = w_rad_s[k, t] * s
            scratch[k, t] = np.sin(s + phase_rad[k, t])
    out[:] = np.dot(scratch, amplitude_n)
    for k in range(out.size):
        f = out[k] + noise_n[k] if noise_n.size else out[k]
        if f < -limit_n:           # comparisons, not min/max: NaN passes, as in np.maximum
            f = -limit_n
        if f > limit_n:
            f = limit_n
        out[k] = f


@numba.njit((_F1, _F1, _F1, _F1), cache=True)
def held_force(start_nl: np.ndarray, command_n: np.ndarray, strut: np.ndarray,
               force: np.ndarray) -> None:
    """``PPHPlant._held_actuator_force``: command times the force constant at the stroke (N).

    ``strut`` is ``[stroke_limit_m, force_constant_linear_per_stroke,
    force_constant_quadratic_per_stroke, half_play_m]``; ``start_nl`` starts with the six
    strokes (m) at the start of the sample. Writes the six forces into ``force``.
    """
    for i in range(6):
        ratio = start_nl[i] / strut[0]
        gain = strut[1] - strut[2] * ratio
        gain = ratio * gain
        force[i] = command_n[i] * (1.0 + gain)


@numba.njit((_F2, _F1, _F1, _F1, _F1, _F1, _F1, numba.int64), cache=True)
def lifted_rows(lifted: np.ndarray, lifted_in: np.ndarray, lifted_out: np.ndarray,
                state: np.ndarray, force_n: np.ndarray, strut: np.ndarray,
                contact_side: np.ndarray, substeps: int) -> int:
    """The lifted product of one sample and how many of its internal steps stay in the regime.

    Writes the state and the held force (N) into ``lifted_in``, the product into
    ``lifted_out``; returns the number of leading internal steps that pass
    ``LiftedSample._leading_rows_hold`` (``substeps``: all of them). ``strut`` as for
    :func:`held_force`.
    """
    limit, half_play = strut[0], strut[3]
    n = state.size
    lifted_in[:n] = state
    lifted_in[n:n + 6] = force_n
    lifted_out[:] = np.dot(lifted, lifted_in)
    for k in range(substeps):
        row = n + 6 * substeps + 18 * k
        for i in range(6):
            if abs(lifted_out[row + i]) > limit:
                return k
            if half_play != 0.0 and not lifted_out[row + 12 + i] * contact_side[i] > half_play:
                return k
    return substeps


@numba.njit((_F2, _F2, _F2, _F2, _F2, _F2, _F1, numba.float64, numba.float64, _F1),
            cache=True)
def accelerometer_reading(out_state: np.ndarray, out_inputs: np.ndarray,
                          state_update: np.ndarray, input_update: np.ndarray, x: np.ndarray,
                          specific_force_m_s2: np.ndarray, noise_m_s2: np.ndarray,
                          range_m_s2: float, lsb_m_s2: float, reading: np.ndarray) -> bool:
    """``AccelerometerBank.sample`` on the filter state ``x`` (updated); True if one clipped.

    ``noise_m_s2`` holds this sample's draws, one per channel; the reading (m/s^2) is
    written into ``reading``.
    """
    out_now = np.dot(out_state, x)
    out_in = np.dot(out_inputs, specific_force_m_s2)
    x[:] = np.dot(state_update, x) + np.dot(input_update, specific_force_m_s2)
    clipped = False
    for i in range(reading.size):
        value = (out_now[0, i] + out_in[0, i]) + noise_m_s2[i]
        kept = value               # NaN passes, as in np.maximum / np.minimum
        if kept < -range_m_s2:
            kept = -range_m_s2
        if kept > range_m_s2 - lsb_m_s2:
            kept = range_m_s2 - lsb_m_s2
        clipped |= kept != value
        reading[i] = np.rint(kept / lsb_m_s2) * lsb_m_s2
    return clipped
