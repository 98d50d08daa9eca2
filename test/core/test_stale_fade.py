"""The watchdog's ramp (core/loop/stale_fade.py): its shape, its turns, its step."""

import numpy as np
import pytest

from hexapod_vibration.core.control.notch import smooth_fade_gain
from hexapod_vibration.core.loop.stale_fade import StaleFade


def _gains(fade: StaleFade, stale: list[bool], ramp: int) -> np.ndarray:
    return np.array([fade.step(s, ramp) for s in stale])


def test_the_fall_is_smooth_and_reaches_zero_after_the_ramp():
    ramp = 100
    gains = _gains(StaleFade(), [True] * (ramp + 5), ramp)
    assert gains[ramp - 1] == 0.0 and gains[ramp - 2] > 0.0 and np.all(gains[ramp:] == 0.0)
    assert np.all(np.diff(gains[:ramp]) < 0.0)
    # no kink at the ends: the first and last steps are tiny next to the middle ones
    steps = -np.diff(np.concatenate([[1.0], gains[:ramp]]))
    assert steps[0] < 0.01 * steps.max() and steps[-1] < 0.01 * steps.max()
    # against a hand calculation of the Blackman ramp at a quarter of the way down
    x = 0.75
    expected = (0.42 * x - 0.5 * np.sin(2 * np.pi * x) / (2 * np.pi)
                + 0.08 * np.sin(4 * np.pi * x) / (4 * np.pi)) / 0.42
    assert gains[24] == pytest.approx(expected, abs=1e-12)


def test_the_rise_mirrors_the_fall_and_ends_at_full_gain():
    ramp = 50
    fade = StaleFade()
    fall = _gains(fade, [True] * ramp, ramp)
    rise = _gains(fade, [False] * (ramp + 3), ramp)
    np.testing.assert_allclose(rise[:ramp - 1], fall[::-1][1:], atol=1e-12)
    assert np.all(rise[ramp - 1:] == 1.0) and fade.full


def test_a_ramp_of_zero_samples_is_the_step():
    fade = StaleFade()
    assert _gains(fade, [False, True, True, False, False], 0).tolist() == [1, 0, 0, 1, 1]


def test_a_fresh_stream_is_at_full_gain_and_not_changed_by_a_new_ramp_length():
    fade = StaleFade()
    assert _gains(fade, [False] * 10, 300).tolist() == [1.0] * 10 and fade.full
    _gains(fade, [True] * 10, 100)                   # 10 % of the way down
    assert fade.step(True, 20) == pytest.approx(smooth_fade_gain(0.85), abs=1e-12)   # 5 % more
