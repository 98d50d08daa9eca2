"""A static plant around a notch supervisor, one closed loop per call (core tests).

``a_n = g + d_n + K u_{n-1}`` (m/s^2): gravity ``g`` on every strut, a 40 Hz disturbance
``d`` (a different amplitude per strut) and a one-sample command hold, so every number the
supervisor derives (G, the bound) follows from ``K`` by hand.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor

FS = 1000.0
GRAVITY = 9.80665
TONE = 40.0


def coupled_gain(coupling: float, gain: float = 0.1) -> np.ndarray:
    """K (6x6, (m/s^2)/N): ``gain`` on the diagonal, ``coupling * gain`` elsewhere."""
    return gain * (np.eye(6) + coupling * (np.ones((6, 6)) - np.eye(6)))


def run(sup: NotchSupervisor, k: np.ndarray, samples: int, start: int = 0,
        amplitude: float = 0.05, skip: frozenset[int] = frozenset(),
        until: Callable[[NotchSupervisor], bool] | None = None) -> np.ndarray:
    """Close the loop for ``samples`` samples; returns the disturbance-free error per sample.

    ``until``: stop before the first sample at which it holds (the rows so far returned).
    """
    u = np.zeros(6)
    residual = np.zeros((samples, 6))
    mix = np.linspace(0.5, 1.5, 6)
    for i, n in enumerate(range(start, start + samples)):
        if until is not None and until(sup):
            return residual[:i]
        d = amplitude * mix * np.cos(2 * np.pi * TONE * n / FS + 0.3)
        accel = GRAVITY + d + k @ u
        residual[i] = d + k @ u
        if n in skip:
            continue
        command = sup.step(n, accel)
        u = np.zeros(6) if command is None else command.copy()
    return residual


def tone_rms(x: np.ndarray) -> float:
    """RMS (m/s^2) of the 40 Hz component of x (samples x 6), by least squares."""
    n = np.arange(x.shape[0])
    basis = np.column_stack([np.cos(2 * np.pi * TONE * n / FS), np.sin(2 * np.pi * TONE * n / FS)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return float(np.sqrt(np.mean(np.sum(coef**2, axis=0) / 2)))
