"""The anti-windup clamp: a ceiling over each strut's tones, and WeightClamps' bookkeeping.

The clamp is the canceller's own (its weights set above the limit and clipped, as the
supervisor's step does after an update); judged guard blocks are given by hand.
"""

import numpy as np
import pytest

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import NotchConfig, Settings
from hexapod_vibration.core.control.supervisor.events import EventLog
from hexapod_vibration.core.control.supervisor.weight_clamps import (
    HELD_BLOCKS,
    HELD_CLAMP_FRACTION,
    WeightClamps,
)
from hexapod_vibration.core.control.weight_ceiling import magnitude_ceiling

FS = 1000.0
BLOCK = 250
LIMIT_N = 0.3


def test_the_ceiling_brings_each_row_to_the_limit_and_keeps_the_small_magnitudes():
    rng = np.random.default_rng(3)
    m = rng.random((500, 5)) * rng.choice([0.01, 1.0, 10.0], size=(500, 5))
    m = m[m.sum(axis=1) > 1.0]
    ceiling = magnitude_ceiling(m, 1.0)
    clipped = np.minimum(m, ceiling[:, None])
    np.testing.assert_allclose(clipped.sum(axis=1), 1.0, rtol=1e-12)
    # a second reader: bisection on sum(min(m, c)) = 1 for each row
    lo, hi = np.zeros(len(m)), m.max(axis=1)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        over = np.minimum(m, mid[:, None]).sum(axis=1) > 1.0
        hi, lo = np.where(over, mid, hi), np.where(over, lo, mid)
    np.testing.assert_allclose(ceiling, 0.5 * (lo + hi), rtol=1e-9)
    assert magnitude_ceiling(np.array([[2.5]]), 0.3)[0] == 0.3


def test_the_clamp_clips_the_largest_tone_and_leaves_the_small_one_whole():
    canceller = AdaptiveNotchCanceller(6, [40.0, 80.0], FS, 0.002)
    weights = np.empty((2, 6), dtype=complex)
    weights[0] = 2.52 * np.exp(0.7j)                # what 40 Hz needs, 80 Hz its 0.024 N
    weights[1] = 0.024 * np.exp(-1.1j)
    canceller.set_weights(weights)
    assert canceller.limit_weights(LIMIT_N)
    after = canceller.weights
    np.testing.assert_array_equal(after[1], weights[1])                   # untouched
    np.testing.assert_allclose(np.abs(after[0]), LIMIT_N - 0.024, rtol=1e-12)
    np.testing.assert_allclose(np.angle(after[0]), 0.7, rtol=1e-12)       # direction kept
    assert np.abs(after).sum(axis=0).max() <= LIMIT_N + 1e-12
    assert not canceller.limit_weights(LIMIT_N) and canceller.clamped_samples == 1


def _clamps() -> tuple[WeightClamps, AdaptiveNotchCanceller, EventLog]:
    config = NotchConfig().replaced({"weight_limit_n": LIMIT_N})
    canceller = AdaptiveNotchCanceller(6, [40.0, 80.0], FS, 0.002)
    events = EventLog()
    return WeightClamps(Settings(config, FS, 6), canceller, events), canceller, events


def _block(clamps, canceller, n_last, clamped):
    """One judged block of BLOCK samples ending at ``n_last``, ``clamped`` of them clamped."""
    for k in range(clamped):
        canceller.set_weights(np.full((2, 6), 1.0 + 0.0j))       # above the limit
        assert canceller.limit_weights(LIMIT_N)
        clamps.clamped(n_last - BLOCK + 1 + k)
    clamps.judged(n_last, BLOCK)


def test_held_after_2_s_of_blocks_clamped_and_said_once_a_second():
    clamps, canceller, events = _clamps()
    _block(clamps, canceller, 999, BLOCK)             # the first judged block only starts
    for k in range(1, HELD_BLOCKS + 1):
        assert not clamps.held and clamps.note() == ""
        _block(clamps, canceller, 999 + BLOCK * k, BLOCK)
    assert clamps.held
    assert "held at weight_limit_n 0.3 N (clamped on 100 % of the samples)" in clamps.note()
    assert clamps.count == BLOCK * (HELD_BLOCKS + 1) == canceller.clamped_samples
    said = [e.message for e in events.drain()]
    assert len(said) == (BLOCK * (HELD_BLOCKS + 1)) // int(FS) + 1
    assert all("clamped to the actuator rating 0.3 N" in m for m in said)
    clamps.restart()
    assert not clamps.held


@pytest.mark.parametrize("case", ["clamped less often", "a block missing"])
def test_fewer_clamps_or_a_broken_run_of_blocks_is_not_held(case):
    clamps, canceller, _ = _clamps()
    clamped = int(HELD_CLAMP_FRACTION * BLOCK) - 1 if case == "clamped less often" else BLOCK
    n = 999
    for k in range(3 * HELD_BLOCKS):
        n += 2 * BLOCK if case == "a block missing" and k % HELD_BLOCKS == 3 else BLOCK
        _block(clamps, canceller, n, clamped)
        assert not clamps.held
