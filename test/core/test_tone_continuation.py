"""The pointing controller's forecast: its last commands' oscillation continued."""

import numpy as np
import pytest
from kernel_calls import numba_files_called

from hexapod_vibration.core.control.tone_continuation import (
    HISTORY_SAMPLES,
    MAX_POLE_RADIUS,
    ToneContinuation,
)
from hexapod_vibration.core.model.kernel_choice import KERNELS_ENV

pytestmark = pytest.mark.unit
FS = 1000.0


@pytest.fixture(params=["compiled", "numpy"])
def kernels(request, monkeypatch) -> str:
    """Each test on both paths: the compiled kernel (where numba is) and NumPy."""
    if request.param == "compiled":
        pytest.importorskip("numba")
    monkeypatch.setenv(KERNELS_ENV, request.param)
    assert (ToneContinuation(6).compiled is None) == (request.param == "numpy")
    return request.param


def _commands(samples: int, seed: int = 0) -> np.ndarray:
    """A 40 Hz oscillation of 1.1 N (a phase per strut) on 45 N, a slow drift, noise."""
    n = np.arange(samples)[:, None]
    rng = np.random.default_rng(seed)
    return (45.0 + 1.1 * np.sin(2 * np.pi * 40.0 * n / FS + np.arange(6))
            + 0.3 * np.sin(2 * np.pi * 2.0 * n / FS) + 0.05 * rng.normal(size=(samples, 6)))


def test_the_continuation_is_closer_than_a_hold_over_the_next_samples(kernels):
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


def test_it_holds_before_the_history_is_full_and_without_an_oscillation(kernels):
    continuation = ToneContinuation(6)
    assert np.array_equal(continuation.forecast(5), np.zeros((5, 6)))
    for n in range(HISTORY_SAMPLES - 1):
        continuation.add(np.full(6, float(n)))
    np.testing.assert_array_equal(continuation.forecast(3), np.full((3, 6), 198.0))
    continuation.add(np.full(6, 199.0))                          # full: a ramp, no oscillation
    np.testing.assert_array_equal(continuation.forecast(3), np.full((3, 6), 199.0))


def test_a_growing_oscillation_is_not_continued_growing(kernels):
    n = np.arange(HISTORY_SAMPLES)[:, None]
    growing = np.exp(n / 50.0) * np.sin(2 * np.pi * 40.0 * n / FS) * np.ones((1, 6))
    continuation = ToneContinuation(6)
    for row in growing:
        continuation.add(row)
    forecast = continuation.forecast(200)
    assert np.all(np.isfinite(forecast))
    swing = np.ptp(forecast[:25], axis=0)                     # one 40 Hz period each
    assert np.all(np.ptp(forecast[-25:], axis=0) <= swing)    # the pole pulled inside


def _reference_forecast(history: np.ndarray, samples: int) -> np.ndarray:
    """A second method: per strut least squares, then the recurrence sample by sample.

    ``np.linalg.lstsq`` of y[k] = a1 y[k-1] + a2 y[k-2] about the mean, then the recurrence
    of the pole pulled to MAX_POLE_RADIUS.
    """
    rows = np.empty((samples, history.shape[1]))
    for c, x in enumerate(history.T):
        mean = x.mean()
        y = x - mean
        (a1, a2), *_ = np.linalg.lstsq(np.column_stack((y[1:-1], y[:-2])), y[2:], rcond=None)
        assert a1 * a1 + 4.0 * a2 < 0.0                        # an oscillation (the signals)
        radius = min(np.sqrt(-a2), MAX_POLE_RADIUS)
        angle = np.arccos(a1 / (2.0 * np.sqrt(-a2)))
        previous, last = y[-2], y[-1]
        for k in range(samples):
            previous, last = last, 2.0 * radius * np.cos(angle) * last - radius**2 * previous
            rows[k, c] = mean + last
    return rows


def test_the_forecast_is_the_fitted_oscillation_continued(kernels):
    """Against a second method: per-strut least squares and the recurrence, step by step."""
    rng = np.random.default_rng(4)
    n = np.arange(HISTORY_SAMPLES + 57)[:, None]
    for frequency_hz, damping in ((40.0, 0.0), (25.0, 0.004), (110.0, -0.001)):
        phases, gains = rng.uniform(0, 2 * np.pi, 6), rng.uniform(0.2, 3.0, 6)
        commands = (45.0 + gains * np.exp(-damping * n)
                    * np.sin(2 * np.pi * frequency_hz * n / FS + phases)
                    + 0.005 * rng.normal(size=(n.size, 6)))
        continuation = ToneContinuation(6)
        for row in commands:
            continuation.add(row)
        expected = _reference_forecast(commands[-HISTORY_SAMPLES:], 200)
        np.testing.assert_allclose(continuation.forecast(200), expected, rtol=0, atol=1e-9)


def test_the_compiled_continuation_is_numpy_s_and_holds_where_it_holds(monkeypatch):
    """Both paths on the same histories: oscillating, constant (singular), a ramp, NaN."""
    pytest.importorskip("numba")
    commands = _commands(HISTORY_SAMPLES + 33, seed=5)
    commands[:, 1] = 45.0                                       # constant: a singular fit
    commands[:, 2] = np.arange(commands.shape[0])               # a ramp: real poles
    commands[-40, 3] = np.nan                                   # not finite: held
    commands[-1, 4] = np.nan                                    # held as NaN, on both paths
    forecasts = {}
    for path in ("compiled", "numpy"):
        monkeypatch.setenv(KERNELS_ENV, path)
        continuation = ToneContinuation(6)
        for row in commands:
            continuation.add(row)
        forecasts[path] = continuation.forecast(200)
    np.testing.assert_allclose(forecasts["compiled"], forecasts["numpy"], rtol=0, atol=1e-9)
    held = forecasts["numpy"][:, 1:5]
    np.testing.assert_array_equal(held, np.broadcast_to(commands[-1, 1:5], held.shape))
    assert np.ptp(forecasts["numpy"][:25, [0, 5]], axis=0).min() > 0.5   # an oscillation


def test_no_python_runs_inside_the_continuation_kernel(monkeypatch):
    """As for the law (test_pointing.py): one call, no numba Python on the way."""
    pytest.importorskip("numba")
    monkeypatch.setenv(KERNELS_ENV, "compiled")
    continuation = ToneContinuation(6)
    for row in _commands(HISTORY_SAMPLES):
        continuation.add(row)
    continuation.forecast(200)
    assert not numba_files_called(lambda: continuation.forecast(200))
