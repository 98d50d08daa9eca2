"""The line under a fixed tone, located from the weights' turning (core/control/line_offset.py)."""

import numpy as np
import pytest

from hexapod_vibration.core.control.line_offset import MIN_COHERENCE, LineOffsetMonitor
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

FS = 1000.0
TONE = 40.0


def _cancel(line_hz: float, samples: int, monitor: LineOffsetMonitor) -> np.ndarray:
    """The paper's canceller (P = I) on the static plant e = d - 0.1 u; the errors.

    Its time constant is about 2 s: 15 s leave its start-up within 0.1 %.
    """
    canceller = AdaptiveNotchCanceller(6, [TONE], FS, 0.01)
    mix = np.linspace(0.5, 1.5, 6)
    rng = np.random.default_rng(3)
    u, errors = np.zeros(6), []
    for n in range(samples):
        d = 0.05 * mix * np.cos(2 * np.pi * line_hz * n / FS + 0.3)
        e = d - 0.1 * u + 1e-4 * rng.standard_normal(6)
        u = canceller.step(e).copy()
        monitor.step(canceller.adapted_weights)
        errors.append(np.abs(e).max())
    return np.array(errors)


@pytest.mark.parametrize("offset_hz", [-0.6, -0.3, 0.0, 0.3, 1.0])
def test_a_real_canceller_s_weights_turn_at_the_line_s_offset_eq_21(offset_hz):
    monitor = LineOffsetMonitor(1, FS)
    errors = _cancel(TONE + offset_hz, 15000, monitor)
    assert monitor.ready
    assert monitor.offset_hz[0] == pytest.approx(offset_hz, abs=0.01)
    assert monitor.coherence[0] > 0.99
    assert errors[-500:].max() < 1.5 * errors[:500].max()     # a stable loop (it may not
    # reduce a line outside its notch: beta about 0.5 rad/s here)


def test_synthetic_weights_two_tones_and_the_sign():
    """(T, C) phasors turning at +0.25 and -1.5 Hz; ready after two time constants."""
    monitor = LineOffsetMonitor(2, FS, block_samples=50, time_constant_s=0.5)
    w0 = np.array([[1 + 1j] * 6, [2.0] * 6])
    rates = np.array([0.25, -1.5])
    for n in range(999):
        monitor.step(w0 * np.exp(2j * np.pi * rates * n / FS)[:, None])
    assert not monitor.ready                                  # 19 blocks < 20
    for n in range(999, 3000):
        monitor.step(w0 * np.exp(2j * np.pi * rates * n / FS)[:, None])
    assert monitor.ready
    np.testing.assert_allclose(monitor.offset_hz, rates, atol=1e-9)
    np.testing.assert_allclose(monitor.coherence, 1.0, atol=1e-9)
    monitor.reset()
    assert not monitor.ready and not monitor.started


def test_weights_that_wander_are_incoherent():
    """No line under the tone: noise-driven weights turn one way and the other."""
    rng = np.random.default_rng(7)
    monitor = LineOffsetMonitor(1, FS)
    w = np.zeros((1, 6), complex)
    for _ in range(5000):
        w = 0.95 * w + (rng.standard_normal((1, 6)) + 1j * rng.standard_normal((1, 6)))
        monitor.step(w)
    assert monitor.ready and monitor.coherence[0] < MIN_COHERENCE


@pytest.mark.parametrize("block, tau", [(0, 0.5), (50, 0.0), (50, float("nan"))])
def test_bad_settings_are_refused(block, tau):
    with pytest.raises(ValueError, match="block_samples"):
        LineOffsetMonitor(1, FS, block, tau)


@pytest.mark.parametrize("lowpass_hz", [0.0, 10.0])
def test_the_canceller_adds_its_adapted_weights_in_place_bit_for_bit(lowpass_hz):
    """``step_from`` (no copy of the weights, the supervisor's 1 kHz path) is ``step``."""
    canceller = AdaptiveNotchCanceller(6, [40.0, 80.0], FS, 0.01)
    canceller.set_update_lowpass(lowpass_hz)
    copied, in_place = LineOffsetMonitor(2, FS), LineOffsetMonitor(2, FS)
    rng = np.random.default_rng(5)
    for n in range(3000):
        canceller.step(np.cos(2 * np.pi * 40.3 * n / FS) * 0.05 + 1e-3 * rng.standard_normal(6))
        assert copied.step(canceller.adapted_weights) == in_place.step_from(canceller)
    assert copied.ready and in_place.ready
    assert np.array_equal(copied.offset_hz, in_place.offset_hz)
    assert np.array_equal(copied.coherence, in_place.coherence)
