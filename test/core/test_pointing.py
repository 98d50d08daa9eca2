"""The pointing law sample by sample against a reference written from its documented equations.

The reference follows the module docstring of ``core/pointing.py`` step by step (pose from
the gaps, PID per axis, anti-windup on the integral's strut forces, statics J^-T, then the
Butterworth low-pass run by ``scipy.signal.sosfilt``), with none of the controller's code.
The law runs on both of its arithmetics (fixture ``kernels``: the compiled kernels of
``core/control/compiled_law.py``, the NumPy path), which must also be equal to each other.
"""

import numpy as np
import pytest
from kernel_calls import numba_files_called
from scipy import signal

from hexapod_vibration.core.control.pointing import PointingGains
from hexapod_vibration.core.loop.signal_ranges import out_of_range
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.kernel_choice import KERNELS_ENV
from hexapod_vibration.core.model.plant import PPHPlant, rigid_body_mass_matrix, saturate_commands
from hexapod_vibration.core.model.sensors import EddySensorArray, pose_from_gaps
from hexapod_vibration.core.sim.closed_loop import make_pointing_controller, strut_stiffness_n_per_m
from hexapod_vibration.paths import config_path

MODEL = load_model_config(config_path("pph_model.yaml"))
SENSING = EddySensorArray(MODEL.eddy, float(MODEL.geometry.top_joints_m[0, 2])).sensing_matrix
FS = MODEL.simulation.sample_rate_hz
STROKE_M = MODEL.strut.stroke_limit_m
SAMPLES = 20000
TARGETS = {3000: np.deg2rad([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
           8000: np.array([0.0, 0.0, 0.0, -np.deg2rad(0.5), np.deg2rad(0.8), 0.0]),
           12000: np.array([2e-4, -1e-4, 5e-4, 0.0, 0.0, np.deg2rad(2.0)]),
           17000: np.zeros(6)}
GAINS = {6000: PointingGains(bandwidth_hz=3.0, damping_ratio=0.5, output_lowpass_hz=25.0,
                             force_limit_n=70.0),
         14000: PointingGains(bandwidth_hz=0.8, damping_ratio=1.2, output_lowpass_hz=8.0,
                              force_limit_n=25.0)}
RESET_AT = 11000


def _gaps(wander: float, seed: int = 1) -> np.ndarray:
    """Eddy gaps (m): pose lagging the target by 0.2 s, offset, wander, 40/80 Hz, noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(SAMPLES) / FS
    target = np.zeros((SAMPLES, 6))
    for n, pose in sorted(TARGETS.items()):
        target[n:] = pose
    lagged = signal.lfilter([1.0 - np.exp(-1.0 / (0.2 * FS))],
                            [1.0, -np.exp(-1.0 / (0.2 * FS))], target, axis=0)
    wander_pose = wander * np.array([2e-6, 2e-6, 1e-6, 2e-4, 2e-4, 2e-4])
    pose = lagged + 2e-6 + wander_pose * np.sin(2 * np.pi * 0.15 * t[:, None]
                                                + rng.uniform(0, 6.3, 6))
    pose += np.outer(np.sin(2 * np.pi * 40.0 * t), rng.normal(0.0, 1e-6, 6))
    pose += np.outer(np.sin(2 * np.pi * 80.0 * t + 0.3), rng.normal(0.0, 3e-7, 6))
    pose += rng.normal(0.0, 1e-7, pose.shape)
    return pose @ SENSING.T


def _run_controller(gaps: np.ndarray, integrals: np.ndarray | None = None) -> np.ndarray:
    """The law's forces (N) for ``gaps`` with the target, gain and reset changes.

    Its integral after each sample goes into ``integrals`` if given.
    """
    law = make_pointing_controller(MODEL, SENSING, FS)
    forces = np.empty_like(gaps)
    for n, sample in enumerate(gaps):
        if n in TARGETS:
            law.set_target(TARGETS[n], STROKE_M)
        if n in GAINS:
            law.set_gains(GAINS[n])
        if n == RESET_AT:
            law.reset()
        forces[n] = law.step(sample)
        if integrals is not None:
            integrals[n] = law._integral
    return forces


def _axis_gains(gains: PointingGains) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-axis Kp, Ki, D of the module docstring for the model's stiffness and masses."""
    jac = MODEL.geometry.top_jacobian
    k = strut_stiffness_n_per_m(MODEL) * np.diag(jac.T @ jac)
    m = np.diag(rigid_body_mass_matrix(MODEL.top_plate))
    w_c = 2.0 * np.pi * gains.bandwidth_hz
    w_n = np.maximum(np.sqrt(k / m), 2.0 * w_c)
    zeta = gains.damping_ratio
    k_i = m * w_c * w_n**2
    k_p = np.maximum(m * (w_n**2 + 2.0 * zeta * w_n * w_c) - k, 0.0)
    d = np.minimum(m * (2.0 * zeta * w_n + w_c), m * 2.0 * np.pi * 3.0)
    return k_p, k_i, d


def _reference(gaps: np.ndarray) -> tuple[np.ndarray, int]:
    """Strut forces (N) from the documented equations, and the number of held integrals."""
    jac_t = MODEL.geometry.top_jacobian.T
    poses = np.linalg.solve(SENSING, gaps.T).T
    gains = PointingGains()
    k_p, k_i, d = _axis_gains(gains)
    target, integral, previous = np.zeros(6), np.zeros(6), None
    raw = np.empty_like(gaps)
    restarts = {0: (gains, False)}             # sample -> low-pass design, keep its output
    held = 0
    for n, pose in enumerate(poses):
        target = TARGETS.get(n, target)
        if n in GAINS:
            gains = GAINS[n]
            k_p, k_i, d = _axis_gains(gains)
            restarts[n] = (gains, True)
        if n == RESET_AT:
            integral, previous = np.zeros(6), None
            restarts[n] = (gains, False)
        rate = np.zeros(6) if previous is None else (pose - previous) * FS
        previous = pose
        error = target - pose
        candidate = integral + error / FS
        if np.max(np.abs(np.linalg.solve(jac_t, k_i * candidate))) > gains.force_limit_n:
            held += 1
        else:
            integral = candidate
        raw[n] = np.linalg.solve(jac_t, k_p * error + k_i * integral - d * rate)
    return _lowpass_segments(raw, restarts), held


def _lowpass_segments(raw: np.ndarray, restarts: dict) -> np.ndarray:
    """2nd-order Butterworth per segment, its output saturated at the segment's limit.

    Each segment starts from the last output after a gain change, else from 0.
    """
    out = np.empty_like(raw)
    starts = sorted(restarts) + [len(raw)]
    for start, stop in zip(starts[:-1], starts[1:], strict=True):
        gains, keep = restarts[start]
        sos = signal.butter(2, gains.output_lowpass_hz, fs=FS, output="sos")
        level = out[start - 1] if keep else np.zeros(6)
        zi = signal.sosfilt_zi(sos)[:, :, None] * level
        filtered = signal.sosfilt(sos, raw[start:stop], axis=0, zi=zi)[0]
        out[start:stop] = np.clip(filtered, -gains.force_limit_n, gains.force_limit_n)
    return out


@pytest.mark.parametrize("wander", [1.0, 30.0])
def test_step_follows_the_documented_law_with_gain_target_and_reset_changes(wander, kernels):
    gaps = _gaps(wander)
    reference, held = _reference(gaps)
    assert 1000 < held < SAMPLES - 5000        # the anti-windup engages and releases
    forces = _run_controller(gaps)
    error = np.max(np.abs(forces - reference))
    assert error <= 1e-12 * np.max(np.abs(reference)), f"max error {error:.3g} N"


def test_step_returns_an_array_of_its_own(kernels):
    gaps = _gaps(1.0)[:300]
    law = make_pointing_controller(MODEL, SENSING, FS)
    assert law.kernels == kernels
    law.set_target(TARGETS[3000], STROKE_M)
    kept = []
    for sample in gaps:
        force = law.step(sample)
        kept.append(force.copy())
        force[:] = 1e9                          # the caller may scribble on it
    again = make_pointing_controller(MODEL, SENSING, FS)
    again.set_target(TARGETS[3000], STROKE_M)
    assert np.array_equal(np.array(kept), np.array([again.step(g) for g in gaps]))


def test_the_compiled_law_equals_the_numpy_law(monkeypatch):
    """Bit for bit, through target, gain and reset changes, the anti-windup and NaN gaps."""
    pytest.importorskip("numba")
    gaps = _gaps(30.0)
    gaps[-5:-2] = np.nan                        # NaN passes both paths alike
    runs = {}
    for path in ("compiled", "numpy"):
        monkeypatch.setenv(KERNELS_ENV, path)
        integrals = np.empty_like(gaps)
        runs[path] = _run_controller(gaps, integrals), integrals
    np.testing.assert_array_equal(runs["compiled"][0], runs["numpy"][0])
    np.testing.assert_array_equal(runs["compiled"][1], runs["numpy"][1])
    assert np.isnan(runs["numpy"][0][-3]).all() and np.isfinite(runs["numpy"][0][:-5]).all()


def test_no_python_runs_inside_the_law_kernel(monkeypatch):
    """As for the plant (test_compiled_sample.py): a Ctrl-C cannot land inside a kernel."""
    pytest.importorskip("numba")
    monkeypatch.setenv(KERNELS_ENV, "compiled")
    law = make_pointing_controller(MODEL, SENSING, FS)
    law.step(np.zeros(6))
    assert not numba_files_called(lambda: [law.step(sample) for sample in _gaps(30.0)[:500]])


def test_linear_state_space_is_the_step_law_without_windup():
    """PointingController.linear_state_space reproduces step() sample for sample."""
    cfg = load_model_config(config_path("pph_model.yaml"))
    sensing = EddySensorArray(cfg.eddy, float(cfg.geometry.top_joints_m[0, 2])).sensing_matrix
    law = make_pointing_controller(cfg, sensing, 1000.0)
    a, b, c, d = law.linear_state_space()
    gaps = 1e-6 * np.random.default_rng(3).normal(size=(400, 6))
    x = np.zeros(a.shape[0])
    x[:6] = gaps[0]                     # the first sample has a zero rate
    for g in gaps:
        expected = law.step(g)
        np.testing.assert_allclose(c @ x + d @ g, expected, rtol=1e-9, atol=1e-12)
        x = a @ x + b @ g


def test_after_its_force_was_zeroed_the_pointing_loop_recovers_within_the_actuator_range():
    """The law's output stays within ``force_limit_n``, so a sag cannot lock the loop up.

    Regression: a restarted driver under load zeroed the pointing stream (late for the
    watchdog's 5 samples), the platform sagged, the law then asked for more than the
    actuator's range, the driver refused every such command (out of range: zero force) and
    the platform never came back.
    """
    limit = MODEL.strut.force_limit_static_n            # the driver's command range (N)
    plant = PPHPlant(MODEL, seed=4)
    law = make_pointing_controller(MODEL, SENSING, FS)
    zeroed = range(3000, 3400)                          # the watchdog's zero force
    sample, forces, tilts = plant.step(np.zeros(6)), [], []
    for n in range(9000):
        command = law.step(sample.eddy_m)
        forces.append(command.copy())
        refused = n in zeroed or out_of_range(command, limit)   # the driver's rules
        applied = np.zeros(6) if refused else command
        sample = plant.step(saturate_commands(np.zeros(6), applied, MODEL.strut))
        tilts.append(np.abs(pose_from_gaps(SENSING, sample.eddy_m)).max())
    forces = np.array(forces)
    assert np.abs(forces).max() <= limit
    assert np.abs(forces[zeroed.stop:]).max() == limit          # it did saturate
    settled = np.array(tilts[:zeroed.start]).max()
    assert max(tilts[-1000:]) <= 2.0 * settled + 1e-6, (settled, max(tilts[-1000:]))
