"""A scenario on the core loop against its uncontrolled twin: the z axis's band levels.

The twin is the same scenario with control never on (same seeds, same identification):
sample for sample the same disturbance. Levels are Welch (4 s Hann segments) band powers
of the top plate's z acceleration, lines included (a band's whole level, dB).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from scipy import signal

from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.sim.closed_loop import CoreLoop, LoopRecord
from hexapod_vibration.core.sim.scenario import Scenario
from hexapod_vibration.core.spectrum import third_octave_bands_hz
from hexapod_vibration.tools.processes import die_with_parent

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
    """(loop, z with control, z of the twin): the scenario and its run without control.

    The two runs are the same run up to control-on (same seeds, control's only difference
    is the sample it turns on at), so that part is simulated once: the process forks there
    and the child runs the twin on (``CoreLoop.advance`` with control never on) while the
    parent runs the scenario; the child's z comes back through a file. Sample for sample
    the twin of two whole runs (``test/core/test_core_twins.py``).
    """
    loop = CoreLoop(CFG, scenario)
    record = loop.new_record()
    loop.advance(record, min(record.control_on_sample, scenario.samples))
    with tempfile.TemporaryDirectory() as folder:
        path, parent = Path(folder) / "twin_z.npy", os.getpid()
        child = os.fork()
        if child == 0:                                  # the twin: control never on
            _run_twin_and_exit(loop, record, path, parent)
        loop.advance(record, scenario.samples)
        z_on = z_axis(loop.finish(record))
        _, status = os.waitpid(child, 0)
        if os.waitstatus_to_exitcode(status) != 0 or not path.exists():
            raise RuntimeError(f"the twin's process failed (exit {status})")
        return loop, z_on, np.load(path)


def z_axis(record: LoopRecord) -> np.ndarray:
    """The top plate's z acceleration (m/s^2) of a run."""
    return CFG.geometry.platform_from_struts(record.accel_m_s2)[:, 2]


def _run_twin_and_exit(loop: CoreLoop, record: LoopRecord, path: Path, parent: int) -> None:
    """In the forked child: the rest of the run without control, its z into ``path``."""
    code = 1
    try:
        die_with_parent(parent)
        record.control_on_sample = loop.scenario.samples        # never reached
        loop.advance(record, loop.scenario.samples)
        np.save(path, z_axis(record))
        code = 0
    finally:
        os._exit(code)                 # never back into pytest: no teardown, no report


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
