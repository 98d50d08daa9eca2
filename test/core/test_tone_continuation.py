"""The pointing controller's forecast: its last commands' oscillation continued."""

import numpy as np
import pytest

from hexapod_vibration.core.control.tone_continuation import (
    HISTORY_SAMPLES,
    ToneContinuation,
)

pytestmark = pytest.mark.unit
FS = 1000.0


def _commands(samples: int, seed: int = 0) -> np.ndarray:
    """A 40 Hz oscillation of 1.1 N (a phase per strut) on 45 N, a slow drift, noise."""
    n = np.arange(samples)[:, None]
    rng = np.random.default_rng(seed)
    return (45.0 + 1.1 * np.sin(2 * np.pi * 40.0 * n / FS + np.arange(6))
            + 0.3 * np.sin(2 * np.pi * 2.0 * n / FS) + 0.05 * rng.normal(size=(samples, 6)))


def test_the_continuation_is_closer_than_a_hold_over_the_next_samples():
    commands = _commands(3000)
    continuation = ToneContinuation(6)
    errors, holds = [], []
    for n in range(2800):
        continuation.add(commands[n])
        if n >= HISTORY_SAMPLES and n % 10 == 0:
            forecast = continuation.forecast(20)
            errors.append(forecast - commands[n + 1:n + 21])
            holds.append(commands[n] - commands[n + 1:n + 21])
    rms = np.sqrt(np.mean(np.square(errors), axis=(0, 2)))      # by samples ahead
    hold = np.sqrt(np.mean(np.square(holds), axis=(0, 2)))
    print("rms error 1/5/20 ahead:", rms[[0, 4, 19]].round(3), "hold:", hold[[0, 4, 19]].round(3))
    assert np.all(rms[:5] < 0.7 * hold[:5]) and rms[19] < hold[19]


def test_it_holds_before_the_history_is_full_and_without_an_oscillation():
    continuation = ToneContinuation(6)
    assert np.array_equal(continuation.forecast(5), np.zeros((5, 6)))
    for n in range(HISTORY_SAMPLES - 1):
        continuation.add(np.full(6, float(n)))
    np.testing.assert_array_equal(continuation.forecast(3), np.full((3, 6), 198.0))
    continuation.add(np.full(6, 199.0))                          # full: a ramp, no oscillation
    np.testing.assert_array_equal(continuation.forecast(3), np.full((3, 6), 199.0))


def test_a_growing_oscillation_is_not_continued_growing():
    n = np.arange(HISTORY_SAMPLES)[:, None]
    growing = np.exp(n / 50.0) * np.sin(2 * np.pi * 40.0 * n / FS) * np.ones((1, 6))
    continuation = ToneContinuation(6)
    for row in growing:
        continuation.add(row)
    forecast = continuation.forecast(200)
    assert np.all(np.isfinite(forecast))
    swing = np.ptp(forecast[:25], axis=0)                     # one 40 Hz period each
    assert np.all(np.ptp(forecast[-25:], axis=0) <= swing)    # the pole pulled inside
