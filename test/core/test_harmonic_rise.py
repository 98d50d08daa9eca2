"""The paper's harmonic rise: control unloads the ball joints, harmonics appear; cancelled.

Scenario ``harmonic_rise`` on the core loop, three runs with the same seeds: never
controlled (the twin: the levels "without control" in the same window), the notch at 40
and 80 Hz (as in Table 1), and the notch at 40 Hz with ``harmonics: 11`` (every harmonic
of 40 Hz up to 480 Hz in the bank, following it).
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.analysis.levels import tone_levels
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.sim.closed_loop import CoreLoop
from hexapod_vibration.core.sim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = load_scenario(ROOT / "config" / "scenarios" / "harmonic_rise.yaml")
CFG = load_model_config(ROOT / "config" / "pph_model.yaml", SCENARIO.model_overrides)
HARMONICS = tuple(40.0 * k for k in range(1, 13))
BETWEEN = [100.0, 140.0]                  # uncontrolled lines between the harmonics


def _levels(scenario):
    loop = CoreLoop(CFG, scenario)
    record = loop.run()
    z = CFG.geometry.platform_from_struts(record.accel_m_s2)[:, 2]
    width = int(scenario.window_s * 1000)
    tones = list(HARMONICS) + BETWEEN
    levels, _, _ = tone_levels(z[-width:], tones)
    return dict(zip(tones, levels, strict=True)), loop, record


@pytest.fixture(scope="module")
def runs():
    off = dataclasses.replace(SCENARIO, control_on_s=SCENARIO.duration_s)
    harm = dataclasses.replace(SCENARIO, notch=dataclasses.replace(   # notch parameter
        SCENARIO.notch, tone_frequencies_hz=(40.0,),                   # harmonics: 11
        settings={**SCENARIO.notch.settings, "harmonics": len(HARMONICS) - 1}))
    return {name: _levels(sc) for name, sc in
            (("off", off), ("notch", SCENARIO), ("harmonics", harm))}


def test_without_control_the_joints_stay_closed_with_control_they_open(runs):
    assert runs["off"][1].plant.fallback_samples == 0
    assert runs["notch"][1].plant.fallback_samples > 1000        # free-play crossings
    force = np.abs(runs["notch"][2].notch_command_n[-10_000:]).max()
    assert 25.0 < force < CFG.strut.force_limit_dynamic_n       # near the rating, unclipped


def test_uncontrolled_harmonics_rise_under_control(runs):
    off, notch = runs["off"][0], runs["notch"][0]
    assert notch[40.0] < off[40.0] - 60.0
    assert notch[80.0] < off[80.0] + 3.0                          # both at the floor
    rises = [notch[f] - off[f] for f in HARMONICS[2:]]            # 120..480 Hz
    assert min(rises) >= 6.0                                      # the paper: +10 at 120
    assert notch[120.0] - off[120.0] >= 20.0


def test_cancelling_the_harmonics_removes_the_rise(runs):
    off, notch, harm = runs["off"][0], runs["notch"][0], runs["harmonics"][0]
    for f in HARMONICS[2:10]:                                     # 120..400 Hz
        assert harm[f] <= notch[f] - 30.0, f
    for f in BETWEEN:                                             # uncontrolled lines
        assert harm[f] <= off[f] + 3.0, f
    assert harm[40.0] < off[40.0] - 60.0
