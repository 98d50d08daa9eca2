"""ActuatedPlant: one sample's commands summed, saturated, held; the test sine added."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hexapod_vibration.core.model.actuation import ActuatedPlant
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import PPHPlant, saturate_commands

CFG = load_model_config(Path(__file__).resolve().parents[2] / "config" / "pph_model.yaml")


def test_apply_holds_the_saturated_sum_and_steps_the_plant():
    actuated = ActuatedPlant(PPHPlant(CFG, seed=3), CFG.strut, 1000.0)
    reference = PPHPlant(CFG, seed=3)
    first = reference.step(np.zeros(6))
    np.testing.assert_array_equal(actuated.pending.accel_m_s2, first.accel_m_s2)
    notch = np.array([100.0, -100.0, 10.0, 0.0, 0.0, 1.0])
    pointing = np.array([5.0, 0.0, -75.0, 0.0, 2.0, 0.0])
    applied = actuated.apply(0, notch, pointing)
    np.testing.assert_array_equal(applied, saturate_commands(notch, pointing, CFG.strut))
    np.testing.assert_array_equal(actuated.pending.accel_m_s2,
                                  reference.step(applied).accel_m_s2)


def test_the_test_sine_is_added_to_the_vibration_command_only_when_on():
    actuated = ActuatedPlant(PPHPlant(CFG, seed=3), CFG.strut, 1000.0)
    zero = np.zeros(6)
    np.testing.assert_array_equal(actuated.apply(0, zero, zero), zero)
    actuated.test_sine.frequency_hz, actuated.test_sine.amplitude_n = 40.0, 2.0
    expected = 2.0 * np.sin(2.0 * np.pi * 40.0 * 7 / 1000.0)
    np.testing.assert_allclose(actuated.apply(7, zero, zero), np.full(6, expected),
                               rtol=0, atol=1e-15)
