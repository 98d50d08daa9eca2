"""A scenario on the core loop against its uncontrolled twin: the z axis's band levels.

The twin is the same scenario with control never on (same seeds, same identification):
sample for sample the same disturbance. Levels are Welch (4 s Hann segments) band powers
of the top plate's z acceleration, lines included (a band's whole level, dB).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy import signal

from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.sim.closed_loop import CoreLoop
from hexapod_vibration.core.sim.scenario import Scenario
from hexapod_vibration.core.spectrum import third_octave_bands_hz

ROOT = Path(__file__).resolve().parents[1]
CFG = load_model_config(ROOT / "config" / "pph_model.yaml")
FS = 1000.0
THIRD_OCTAVES = third_octave_bands_hz(5.0, 450.0)[:, 1:]
"""(lo, hi) Hz of every one-third-octave band 5..450 Hz (the contract's bands)."""


def band_db(z: np.ndarray, bands: np.ndarray) -> np.ndarray:
    """Total power (lines included) of z in each [lo, hi) band, dB."""
    f, p = signal.welch(z, FS, window="hann", nperseg=4000)
    return np.array([10 * np.log10(np.sum(p[(f >= lo) & (f < hi)])) for lo, hi in bands])


def run_with_twin(scenario: Scenario) -> tuple[CoreLoop, np.ndarray, np.ndarray]:
    """(loop, z with control, z of the twin): the scenario and its run without control."""
    runs = []
    for sc in (scenario, dataclasses.replace(scenario, control_on_s=scenario.duration_s)):
        loop = CoreLoop(CFG, sc)
        runs.append((loop, CFG.geometry.platform_from_struts(loop.run().accel_m_s2)[:, 2]))
    (loop, z_on), (_, z_off) = runs
    return loop, z_on, z_off


def window_rises_db(scenario: Scenario, z_on: np.ndarray, z_off: np.ndarray,
                    bands: np.ndarray) -> np.ndarray:
    """(W, B) band rises (dB) over the twin in every window of the report's length.

    The windows are ``window_s`` long and start every second from control-on (the
    report's ``bands_over_time``): the start of control and a fade are in them.
    """
    n = int(scenario.window_s * FS)
    starts = range(int(scenario.control_on_s * FS), z_on.size - n + 1, int(FS))
    return np.array([band_db(z_on[a:a + n], bands) - band_db(z_off[a:a + n], bands)
                     for a in starts])


def worst_window_rise(scenario: Scenario, z_on: np.ndarray, z_off: np.ndarray,
                      bands: np.ndarray) -> float:
    """The largest band rise (dB) in any window of the report's length from control-on."""
    return float(np.max(window_rises_db(scenario, z_on, z_off, bands)))
