"""The LTI plant of the exact bound against the simulated plant's own identification."""

import dataclasses

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.sim.closed_loop import CoreLoop
from hexapod_vibration.core.sim.scenario import load_scenario
from hexapod_vibration.paths import config_path, scenario_path
from hexapod_vibration.sweep.loop_model import canceller_plant, frequency_response

CFG = load_model_config(config_path("pph_model.yaml"))
TONES = (40.0, 80.0)


def test_model_response_matches_the_identification_on_the_linear_plant():
    """Two methods: the state-space model's G and the least-squares identification."""
    sc = load_scenario(scenario_path("single_tone_harmonic"))
    sc = dataclasses.replace(sc, nonlinear=False, duration_s=4.0, identify_at_s=0.5,
                             control_on_s=4.0, window_s=1.0,
                             notch=dataclasses.replace(sc.notch, tone_frequencies_hz=TONES,
                                                       settings={"identification": "tones",
                                                                 "mu_policy": "manual"}))
    identified = CoreLoop(CFG, sc).run().plant_response
    plant = canceller_plant(CFG)
    modelled = frequency_response(plant, TONES, CFG.simulation.sample_rate_hz)
    error = np.linalg.norm(modelled - identified, axis=(1, 2)) / np.linalg.norm(
        identified, axis=(1, 2))
    assert np.all(error < 0.03), error
    assert np.max(np.abs(np.linalg.eigvals(plant[0]))) < 1.0       # stable with pointing on
    # the exact bound of the PPH's decentralized notch is far below eq. 18's averaged one
    p = adaptation.normalized_coefficients(modelled[:1], "decentralized")
    exact = adaptation.exact_mu_bound(plant, TONES[:1], 1000.0, p, mu_max=1.0)
    assert 0.002 < exact < 0.1 * adaptation.mu_bound(modelled[:1], p, 2.0)
