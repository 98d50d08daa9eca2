"""The pointing law's input across samples its controller skipped or lost (GapBridge)."""

import numpy as np

from hexapod_vibration.contract import StrutSample
from hexapod_vibration.core.control.gap_bridge import MAX_BRIDGED_SAMPLES, GapBridge
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.sensors import EddySensorArray
from hexapod_vibration.core.sim.closed_loop import make_pointing_controller
from hexapod_vibration.paths import config_path

MODEL = load_model_config(config_path("pph_model.yaml"))
SENSING = EddySensorArray(MODEL.eddy, float(MODEL.geometry.top_joints_m[0, 2])).sensing_matrix
FS = MODEL.simulation.sample_rate_hz
SAMPLES = 6000
GAP_EVERY = 500
"""A gap starts every this many samples (after the continuation's history is full)."""
KICK_WINDOW = 40
"""Samples after a gap over which its kick is taken."""


def _eddy_gaps(seed: int = 3) -> np.ndarray:
    """Eddy gaps (m, (SAMPLES, 6)) as in a realtime ``single_tone_harmonic`` run's bag.

    1e-4 m at 40 Hz, its harmonics at 4 % and 1.4 % of that, noise.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(SAMPLES)[:, None] / FS
    gaps = np.zeros((SAMPLES, 6))
    for hz, amplitude_m in ((40.0, 1e-4), (80.0, 4e-6), (120.0, 1.4e-6)):
        gaps += amplitude_m * np.sin(2 * np.pi * hz * t + rng.uniform(0, 6.3, 6))
    return gaps + rng.normal(0.0, 1e-7, gaps.shape)


def _gap_samples(length: int) -> set[int]:
    return {n for start in range(GAP_EVERY, SAMPLES - GAP_EVERY, GAP_EVERY)
            for n in range(start, start + length)}


def _law_forces(gaps: np.ndarray, missing: set[int], received: set[int],
                bridge: GapBridge | None) -> dict[int, np.ndarray]:
    """The law's command (N) at each sample acted on.

    ``missing``: samples not acted on, of them ``received`` handed over as skipped;
    ``bridge`` None: the law stepped once per sample acted on (across a gap too).
    """
    law = make_pointing_controller(MODEL, SENSING, FS)
    forces, skipped = {}, []
    for n, values in enumerate(gaps):
        if n in missing:
            if n in received:
                skipped.append(StrutSample(values, n, 1))
            continue
        inputs = [values] if bridge is None else bridge.inputs(n, values, skipped)
        for sample in inputs:
            force = law.step(sample)
        forces[n], skipped = force.copy(), []
    return forces


def _kicks(forces: dict[int, np.ndarray], reference: dict[int, np.ndarray]) -> np.ndarray:
    """Per gap, its kick (N) on ``forces`` against ``reference``.

    The largest change of their difference over the ``KICK_WINDOW`` samples acted on after
    the gap (an offset it leaves behind is not a kick).
    """
    acted = sorted(forces)
    diff = np.array([forces[n] - reference[n] for n in acted])
    ends = [i for i in range(1, len(acted)) if acted[i] - acted[i - 1] > 1]
    return np.array([np.abs(diff[i:i + KICK_WINDOW] - diff[i - 1]).max() for i in ends])


def test_received_samples_cross_the_gap_exactly() -> None:
    gaps = _eddy_gaps()
    reference = _law_forces(gaps, set(), set(), None)
    missing = _gap_samples(10)
    bridged = _law_forces(gaps, missing, missing, GapBridge(6))
    assert all(np.array_equal(bridged[n], reference[n]) for n in bridged)


def test_lost_samples_are_continued_not_stepped_over() -> None:
    gaps = _eddy_gaps()
    reference = _law_forces(gaps, set(), set(), None)
    missing = _gap_samples(10)
    received = missing - _gap_samples(3)          # the 3 oldest of each gap lost, 7 queued
    once = _kicks(_law_forces(gaps, missing, set(), None), reference)
    lost_all = _kicks(_law_forces(gaps, missing, set(), GapBridge(6)), reference)
    lost_some = _kicks(_law_forces(gaps, missing, received, GapBridge(6)), reference)
    assert len(once) == len(lost_all) == len(lost_some) == SAMPLES // GAP_EVERY - 2
    assert once.max() > 0.5                       # a real kick to remove (N)
    assert lost_all.max() < 0.1 * once.max()
    assert lost_some.max() <= lost_all.max()


def test_stand_ins_are_counted_and_long_gaps_are_not_filled() -> None:
    bridge, values = GapBridge(6), np.ones(6)
    assert len(bridge.inputs(0, values)) == 1
    received = [StrutSample(np.full(6, 2.0), 3, 1)]
    inputs = bridge.inputs(5, values, received)           # 1, 2 lost; 3 received; 4 lost
    assert len(inputs) == 5 and bridge.stood_in == 3
    assert np.array_equal(inputs[2], received[0].values) and inputs[-1] is values
    far = 5 + MAX_BRIDGED_SAMPLES + 2
    inputs = bridge.inputs(far, values, [StrutSample(np.full(6, 4.0), far - 1, 1)])
    assert [row[0] for row in inputs] == [4.0, 1.0] and bridge.stood_in == 3


def test_first_repeated_and_new_run_samples_are_given_alone() -> None:
    bridge, values = GapBridge(6), np.zeros(6)
    bridge.inputs(100, values)
    assert len(bridge.inputs(100, values)) == 1           # not after the last: no gap
    bridge.reset()
    assert len(bridge.inputs(7, values)) == 1             # a new run starts afresh
    assert len(bridge.inputs(9, values)) == 2 and bridge.stood_in == 1
