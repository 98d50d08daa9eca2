"""Per-sample filters against straightforward references: sosfilt and plain Python."""

import numpy as np
import pytest
from scipy import signal

from hexapod_vibration.core.control.filters import DCBlocker, SosFilterBank

FS = 1000.0
CHANNELS = 6
SAMPLES = 20000
DESIGNS = {
    "pointing low-pass, 1 section": signal.butter(2, 15.0, fs=FS, output="sos"),
    "8th-order low-pass at 3 Hz, 4 sections": signal.butter(8, 3.0, fs=FS, output="sos"),
    "elliptic band-pass 35-45 Hz, 4 sections": signal.ellip(4, 0.5, 60.0, [35.0, 45.0],
                                                           btype="bandpass", fs=FS,
                                                           output="sos"),
}


def _forces(samples: int = SAMPLES, seed: int = 3) -> np.ndarray:
    """Strut-force-like signals (N): offsets, steps, 40 and 80 Hz tones, noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(samples)[:, None] / FS
    x = rng.normal(0.0, 20.0, CHANNELS) + 5.0 * np.sin(2 * np.pi * 40.0 * t)
    x = x + 2.0 * np.sin(2 * np.pi * 80.0 * t + rng.uniform(0, 6.3, CHANNELS))
    x[samples // 3:] += rng.normal(0.0, 30.0, CHANNELS)
    return x + rng.normal(0.0, 0.5, x.shape)


def _accel(samples: int = SAMPLES, seed: int = 4) -> np.ndarray:
    """Accelerometer-like samples (m/s^2): gravity share, slow drift, tones, 16-bit steps."""
    rng = np.random.default_rng(seed)
    t = np.arange(samples)[:, None] / FS
    x = 9.80665 * rng.uniform(0.3, 0.6, CHANNELS) + 0.02 * np.sin(2 * np.pi * 0.05 * t)
    x = x + 0.3 * np.sin(2 * np.pi * 40.0 * t + rng.uniform(0, 6.3, CHANNELS))
    x = x + 0.05 * np.sin(2 * np.pi * 80.0 * t) + rng.normal(0.0, 0.01, x.shape)
    lsb = 2.0 * 2.0 * 9.80665 / 2**16
    return np.round(x / lsb) * lsb


def _bank(sos: np.ndarray, kernels: str) -> SosFilterBank:
    """A bank on the path ``kernels`` names (fixture ``kernels``, test/core/conftest.py)."""
    bank = SosFilterBank(sos, CHANNELS)
    assert (bank.compiled is not None) == (kernels == "compiled")
    return bank


def _run(step, x: np.ndarray) -> np.ndarray:
    return np.array([step(row) for row in x])


def _assert_close(actual: np.ndarray, reference: np.ndarray, rtol: float = 1e-12) -> None:
    error = np.max(np.abs(actual - reference))
    assert error <= rtol * np.max(np.abs(reference)), f"max error {error:.3g}"


@pytest.mark.parametrize("name", DESIGNS)
def test_sos_bank_matches_sosfilt_over_a_whole_sequence(name, kernels):
    sos, x = DESIGNS[name], _forces()
    _assert_close(_run(_bank(sos, kernels).step, x), signal.sosfilt(sos, x, axis=0))


@pytest.mark.parametrize("name", DESIGNS)
def test_sos_bank_reset_is_sosfilt_from_the_steady_state(name, kernels):
    sos, x = DESIGNS[name], _forces()
    bank, half = _bank(sos, kernels), SAMPLES // 2
    bank.reset(x[0])
    first = _run(bank.step, x[:half])
    bank.reset(x[half])
    second = _run(bank.step, x[half:])
    reference = np.vstack([_sosfilt_from_steady(sos, x[:half], x[0]),
                           _sosfilt_from_steady(sos, x[half:], x[half])])
    _assert_close(np.vstack([first, second]), reference)


def test_sos_bank_scalar_reset_and_returned_arrays_are_its_own(kernels):
    sos, x = DESIGNS["pointing low-pass, 1 section"], _forces(200)
    bank = _bank(sos, kernels)
    bank.reset(1.5)
    outputs = []
    for row in x:
        y = bank.step(row)
        outputs.append(y.copy())
        y[:] = 1e9                                  # the caller may scribble on it
    _assert_close(np.array(outputs), _sosfilt_from_steady(sos, x, np.full(CHANNELS, 1.5)))


def _sosfilt_from_steady(sos: np.ndarray, x: np.ndarray, level: np.ndarray) -> np.ndarray:
    """``sosfilt`` along the samples from the steady state of a constant ``level``."""
    zi = signal.sosfilt_zi(sos)[:, :, None] * level
    return signal.sosfilt(sos, x, axis=0, zi=zi)[0]


def test_butter_lowpass_rejects_a_corner_outside_the_band():
    for corner in (0.0, 500.0, -1.0):
        with pytest.raises(ValueError):
            SosFilterBank.butter_lowpass(2, corner, FS, CHANNELS)


def _dc_blocker_reference(x: np.ndarray, r: float, reset_at: int | None = None) -> np.ndarray:
    """``y[n] = x[n] - x[n-1] + r y[n-1]`` in plain Python floats; x[-1] = x[0], y[-1] = 0."""
    out = []
    for n, row in enumerate(x.tolist()):
        if n == 0 or n == reset_at:
            x_prev, y_prev = row, [0.0] * len(row)
        y = [xi - xp + r * yp for xi, xp, yp in zip(row, x_prev, y_prev, strict=True)]
        out.append(y)
        x_prev, y_prev = row, y
    return np.array(out)


@pytest.mark.parametrize("cutoff_hz", [0.5, 5.0])
def test_dc_blocker_is_the_plain_recursion_bit_for_bit(cutoff_hz):
    x, reset_at = _accel(), 7000
    blocker = DCBlocker(CHANNELS, FS, cutoff_hz)
    assert blocker.r == np.exp(-2.0 * np.pi * cutoff_hz / FS)
    first = _run(blocker.step, x[:reset_at])
    blocker.reset()
    second = _run(blocker.step, x[reset_at:])
    reference = _dc_blocker_reference(x, blocker.r, reset_at)
    assert np.array_equal(np.vstack([first, second]), reference)


def test_dc_blocker_constant_input_gives_zero_and_outputs_are_its_own():
    blocker = DCBlocker(CHANNELS, FS)
    level = np.linspace(-9.8, 9.8, CHANNELS)
    for _ in range(5):
        y = blocker.step(level)
        assert np.array_equal(y, np.zeros(CHANNELS))
        y[:] = 1e9                                  # the caller may scribble on it
    x = _accel(500)
    blocker = DCBlocker(CHANNELS, FS)
    outputs = []
    for row in x:
        y = blocker.step(row)
        outputs.append(y.copy())
        y[:] = 1e9
    assert np.array_equal(np.array(outputs), _dc_blocker_reference(x, blocker.r))


def test_dc_blocker_rejects_a_cutoff_outside_the_band():
    for cutoff in (0.0, 500.0):
        with pytest.raises(ValueError):
            DCBlocker(CHANNELS, FS, cutoff)
