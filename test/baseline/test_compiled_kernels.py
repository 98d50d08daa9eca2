"""The compiled (numba) kernels step exactly as the NumPy notch and FxLMS they time."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from hexapod_vibration.baseline.compiled_kernels import CompiledFxlms, CompiledNotch
from hexapod_vibration.bench.compiled_costs import measure_compiled_costs
from hexapod_vibration.bench.controllers import make_fxlms, make_notch, tone_frequencies
from hexapod_vibration.bench.summary import _summary_compiled
from hexapod_vibration.bench.timing import QUICK_TIMING
from hexapod_vibration.core.control.phasor import RESYNC_SAMPLES

# more than one phasor re-synchronisation, and the FxLMS warm-up (L + N - 1 samples)
SAMPLES = 2 * RESYNC_SAMPLES + 300


def _errors(n_channels: int, samples: int = SAMPLES, seed: int = 3) -> np.ndarray:
    return 0.01 * np.random.default_rng(seed).standard_normal((samples, n_channels))


def _numpy_commands(controller, errors: np.ndarray) -> np.ndarray:
    return np.array([controller.step(e) for e in errors])


def _compiled_commands(kernel, errors: np.ndarray, split: int) -> np.ndarray:
    """Run in two blocks: the state must carry over between calls."""
    out = np.zeros_like(errors)
    kernel.run(errors[:split], out[:split])
    kernel.run(errors[split:], out[split:])
    return out


@pytest.mark.parametrize(("channels", "tones"), [(6, 1), (6, 8), (3, 16)])
def test_compiled_notch_gives_the_numpy_notch_commands(channels, tones):
    notch = make_notch(channels, tones, centralized=False, seed=tones)
    errors = _errors(channels)
    for e in errors[:37]:                       # start from a state with nonzero weights
        notch.step(e)
    kernel = CompiledNotch(notch)
    expected = _numpy_commands(notch, errors)
    got = _compiled_commands(kernel, errors, split=RESYNC_SAMPLES - 5)
    assert np.max(np.abs(expected)) > 1e-4
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))


@pytest.mark.parametrize(("path_taps", "tones"), [(32, 1), (64, 2), (128, 3)])
def test_compiled_fxlms_gives_the_numpy_fxlms_commands(path_taps, tones):
    freqs = tuple(tone_frequencies(tones)) if tones > 1 else (40.0,)
    fxlms = make_fxlms(path_taps, 32, tones_hz=freqs, seed=path_taps)
    kernel = CompiledFxlms(fxlms)
    errors = _errors(6)
    expected = _numpy_commands(fxlms, errors)
    got = _compiled_commands(kernel, errors, split=path_taps + 7)
    warmup = path_taps + 32 - 1
    assert np.max(np.abs(expected[:warmup])) == 0.0       # no weights before adaptation
    assert np.max(np.abs(expected)) > 1e-3
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))


def test_compiling_copies_the_controller_state():
    notch = make_notch(6, 4, centralized=False)
    fxlms = make_fxlms(64, 32)
    weights, phases = notch.weights, notch.phases_rad
    errors = _errors(6, samples=100)
    CompiledNotch(notch).run(errors, np.zeros_like(errors))
    CompiledFxlms(fxlms).run(errors, np.zeros_like(errors))
    np.testing.assert_array_equal(notch.weights, weights)
    np.testing.assert_array_equal(notch.phases_rad, phases)
    assert not np.any(fxlms.weights)


def test_compiled_notch_refuses_states_it_does_not_model():
    with pytest.raises(ValueError, match="diagonal P"):
        CompiledNotch(make_notch(6, 2, centralized=True))
    disabled = make_notch(6, 2, centralized=False)
    disabled.set_enabled(False)
    with pytest.raises(ValueError, match="enabled"):
        CompiledNotch(disabled)
    fading = make_notch(6, 2, centralized=False)
    fading.set_tone_frequencies([40.0])
    with pytest.raises(ValueError, match="fading"):
        CompiledNotch(fading)
    lowpassed = make_notch(6, 2, centralized=False)
    lowpassed.set_update_lowpass(10.0)
    with pytest.raises(ValueError, match="no update low-pass"):
        CompiledNotch(lowpassed)
    type_2 = make_notch(6, 2, centralized=False)
    type_2.set_integral_ratio(0.5)
    with pytest.raises(ValueError, match="first-order update"):
        CompiledNotch(type_2)


def test_compiled_fxlms_refuses_a_used_or_frozen_controller():
    used = make_fxlms(32, 32)
    used.step(np.zeros(6))
    with pytest.raises(ValueError, match="fresh"):
        CompiledFxlms(used)
    frozen = make_fxlms(32, 32)
    frozen.set_frozen(True)
    with pytest.raises(ValueError, match="fresh"):
        CompiledFxlms(frozen)


def test_bench_skips_the_compiled_comparison_without_numba(monkeypatch):
    monkeypatch.setitem(sys.modules, "numba", None)
    result = measure_compiled_costs(QUICK_TIMING)
    assert result == {"compiled": {"skipped": "numba is not installed"}}
    lines = _summary_compiled(result)
    assert "not measured (numba is not installed)" in lines[0]
