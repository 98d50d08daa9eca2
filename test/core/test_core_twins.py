"""The twin of ``test/core_twins.py``: forked at control-on, it is the twin of two whole runs.

``run_with_twin`` simulates the part before control-on once and forks there (the child runs
on without control); ``CoreLoop.advance`` runs a scenario in pieces. Both must give, sample
for sample, what two whole runs (``CoreLoop.run``) of the scenario and of its twin give.
"""

import dataclasses

import numpy as np
from core_twins import CFG, run_with_twin, z_axis

from hexapod_vibration.core.sim.closed_loop import CoreLoop
from hexapod_vibration.core.sim.scenario import scenario_from_dict

SHORT = {
    "name": "short_twin", "seed": 11, "duration_s": 7.0, "identify_at_s": 0.2,
    "control_on_s": 6.0, "window_s": 2.0,
    "shaker": {"frequencies_hz": [40.0], "amplitudes_n": [80.0], "noise_rms_n": 0.5},
    "notch": {"preset": "paper", "tone_frequencies_hz": [40.0], "mu": 0.01,
              "adaptation": "decentralized"},
}
"""A Table 1 tone on a short timeline (the paper's 3.2 s test tones identify the plant)."""


def _whole_run_z(scenario) -> np.ndarray:
    return z_axis(CoreLoop(CFG, scenario).run())


def test_the_forked_twin_is_the_twin_of_two_whole_runs():
    scenario = scenario_from_dict(SHORT)
    loop, z_on, z_off = run_with_twin(scenario)
    never_on = dataclasses.replace(scenario, control_on_s=scenario.duration_s)
    np.testing.assert_array_equal(z_on, _whole_run_z(scenario))
    np.testing.assert_array_equal(z_off, _whole_run_z(never_on))
    on = int(scenario.control_on_s * 1000)
    np.testing.assert_array_equal(z_on[:on], z_off[:on])        # one run up to control-on
    assert np.std(z_on[-1000:]) < 0.5 * np.std(z_off[-1000:])    # then control acts
    assert loop.notch.status()["state"] == "adapting"


def test_a_run_in_pieces_is_the_run_in_one_piece():
    scenario = scenario_from_dict(SHORT)
    loop = CoreLoop(CFG, scenario)
    record = loop.new_record()
    for stop in (1, 2500, 2500, 6001, scenario.samples):
        loop.advance(record, stop)
    whole = CoreLoop(CFG, scenario).run()
    loop.finish(record)
    np.testing.assert_array_equal(record.accel_m_s2, whole.accel_m_s2)
    np.testing.assert_array_equal(record.notch_command_n, whole.notch_command_n)
    assert record.notes == whole.notes
