"""The driver's rolling percentiles against numpy's over the same values."""

import math

import numpy as np
import pytest

from hexapod_vibration.core.loop.rolling_percentiles import (
    BLOCK_VALUES,
    BLOCKS,
    FINE_WIDTH_MS,
    RollingPercentiles,
)

pytestmark = pytest.mark.unit


def _filled(values):
    window = RollingPercentiles()
    for v in values:
        window.add(float(v))
    return window


def test_empty_window_reports_nan():
    window = RollingPercentiles()
    assert all(math.isnan(v) for v in window.percentiles((50, 99)))
    assert math.isnan(window.maximum()) and len(window) == 0


def test_percentiles_within_one_bin_above_numpys_nearest_rank():
    rng = np.random.default_rng(3)
    values = np.concatenate([rng.gamma(2.0, 0.15, 4000), rng.uniform(20.0, 300.0, 40)])
    window = _filled(values)
    for q, got in zip((50, 90, 99, 99.9), window.percentiles((50, 90, 99, 99.9)), strict=True):
        exact = np.percentile(values, q, method="inverted_cdf")
        width = FINE_WIDTH_MS if exact < 20.0 else 0.01 * exact
        assert exact <= got <= exact + width + 1e-12, q
    assert window.maximum() == values.max()


def test_only_the_last_blocks_count():
    old = [100.0] * (BLOCK_VALUES * 2)                       # pushed out of the window
    recent = [0.5] * (BLOCK_VALUES * BLOCKS)
    window = _filled(old + recent)
    assert window.percentiles((100,)) == [pytest.approx(0.51)]
    assert window.maximum() == 0.5 and len(window) == BLOCK_VALUES * BLOCKS
    assert window.count == len(old) + len(recent)


def test_huge_and_negative_values_land_in_the_end_bins():
    window = _filled([-1.0, 1e9])
    low, high = window.percentiles((50, 100))
    assert low == pytest.approx(FINE_WIDTH_MS) and high > 1e6
    assert window.maximum() == 1e9
