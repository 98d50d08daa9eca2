"""Physical ranges of the loop signals (core/loop/signal_ranges.py), checked by hand."""

import numpy as np

from hexapod_vibration.core.loop.signal_ranges import (
    PYTHON_CHECK_MAX_VALUES,
    SignalRanges,
    out_of_range,
)
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import PPHPlant
from hexapod_vibration.core.model.sensors import AccelerometerBank
from hexapod_vibration.paths import config_path

MODEL = load_model_config(config_path("pph_model.yaml"))
RANGES = SignalRanges.from_model(MODEL)


def test_ranges_of_the_packaged_model():
    assert RANGES.accel_m_s2 == 2.0 * 9.80665                  # +-2 g
    assert RANGES.command_n == MODEL.strut.force_limit_static_n == 70.0
    assert 0.03 < RANGES.eddy_m < 0.08                          # 2 x 35 mm


def test_every_accelerometer_reading_is_within_its_range():
    bank = AccelerometerBank(MODEL.accelerometer, 10000.0, 1000.0, seed=3)
    huge = np.full((bank.substeps, 6), 1e3)
    readings = np.array([bank.sample(sign * huge) for sign in (1.0, -1.0) for _ in range(50)])
    assert np.max(np.abs(readings)) >= RANGES.accel_m_s2 - bank.lsb_m_s2   # clipped
    assert not out_of_range(readings, RANGES.accel_m_s2)


def test_eddy_gaps_at_full_stroke_are_within_the_range():
    """All six struts at the stroke limit, in every sign pattern: gaps stay in range."""
    geometry = MODEL.geometry
    plant = PPHPlant(MODEL, seed=0)
    worst = 0.0
    for pattern in range(64):
        signs = np.array([1.0 if pattern >> k & 1 else -1.0 for k in range(6)])
        pose = np.linalg.solve(geometry.top_jacobian, signs * MODEL.strut.stroke_limit_m)
        worst = max(worst, float(np.max(np.abs(plant.eddy.sensing_matrix @ pose))))
    assert worst <= RANGES.eddy_m / 2 + 1e-12
    assert worst > RANGES.eddy_m / 2 * 0.5        # the bound is not loose by orders


def test_out_of_range_gives_a_reason():
    assert out_of_range(np.ones(6), 1.0) == ""
    reason = out_of_range(np.array([0, 0, 1e300, 0, 0, 0]), 20.0)
    assert "1e+300" in reason and "20" in reason


def test_both_paths_of_the_check_agree_and_a_nan_is_beyond_any_range():
    """Six values take the Python floats' path, a forecast's 1 200 NumPy's: same verdicts."""
    rng = np.random.default_rng(3)
    for size in (1, 6, PYTHON_CHECK_MAX_VALUES, PYTHON_CHECK_MAX_VALUES + 1, 1200):
        values = rng.uniform(-20.0, 20.0, size)
        assert out_of_range(values, 20.0) == ""                   # the bound is within
        for bad in (20.000001, -25.0, np.nan, np.inf, -np.inf):
            spoiled = values.copy()
            spoiled[size // 2] = bad
            assert out_of_range(spoiled, 20.0).startswith("|value| "), (size, bad)
