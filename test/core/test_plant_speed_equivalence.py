"""The per-call optimisations of PPHPlant.step change no number, compiled or in NumPy.

A reference implementation of one sample, written the plain way (``Shaker.force_n``,
``np.clip``, the start and regime tests evaluated in full every sample, fresh arrays),
drives a second plant built with the same seeds; both must give the same samples, the
same random noise streams and the same counters. Each test runs the optimised plant on
both of its arithmetics (``kernels``: the compiled kernels, the NumPy path).
"""

import numpy as np
import pytest

from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import N_DOF, N_INPUT, N_STATE, PPHPlant
from hexapod_vibration.core.model.sensors import AccelerometerBank
from hexapod_vibration.core.model.shaker import Shaker, tones_from_arrays
from hexapod_vibration.paths import config_path

CFG = load_model_config(config_path("pph_model.yaml"))
FIELDS = ("accel_m_s2", "eddy_m", "applied_force_n", "top_accel_true", "relative_pose_true",
          "stroke_m")
TONES = tones_from_arrays([40.0, 80.0, 120.0], [80.0, 16.0, 12.0])     # paper Table 1
DRIFTING = tones_from_arrays([40.0, 80.0, 120.0], [80.0, 16.0, 12.0], [0.3, 1.0, -2.0],
                             drift_hz=2.0, drift_period_s=7.0)


def _reference_accelerometer(bank: AccelerometerBank, specific_force: np.ndarray) -> np.ndarray:
    filtered = (bank._out_state @ bank._x + bank._out_inputs @ specific_force)[0]
    bank._x = bank._state_update @ bank._x + bank._input_update @ specific_force
    value = filtered + bank._rng.normal(0.0, bank.noise_rms_m_s2, filtered.shape[0])
    clipped = np.clip(value, -bank.range_m_s2, bank.range_m_s2 - bank.lsb_m_s2)
    if (clipped != value).any():
        bank.clipped_samples += 1
    return np.round(clipped / bank.lsb_m_s2) * bank.lsb_m_s2


def _reference_regime_holds(plant: PPHPlant, nl_rows: np.ndarray, start_nl: np.ndarray) -> bool:
    rows = nl_rows.reshape(plant.substeps, 18)[:-1]
    if max(rows[:, 0:6].max(), -rows[:, 0:6].min()) > plant.config.strut.stroke_limit_m:
        return False
    half_play = 0.5 * plant.config.strut.joint_free_play_m
    if half_play == 0.0:
        return True
    side = np.sign(start_nl[12:18])
    return bool((rows[:, 12:18] * side).min() > half_play
                and (start_nl[12:18] * side).min() > half_play)


def _reference_lifted_step(plant: PPHPlant, actuator: np.ndarray, shaker: np.ndarray) -> bool:
    n, ns = N_STATE, plant.substeps
    stop, play = plant._stop_and_play(plant._nl)
    if stop.any():
        return False
    v = np.zeros(n + N_INPUT + ns)
    v[n + 13] = 1.0                                   # gravity input
    v[:n], v[n:n + 6], v[n + 6:n + 12], v[n + N_INPUT:] = plant.state, actuator, play, shaker
    out = plant._lifted.matrix @ v
    nl_rows = out[n + 6 * ns:n + 24 * ns]
    if not _reference_regime_holds(plant, nl_rows, plant._nl):
        return False
    plant.set_state(out[:n])
    plant._acc[:] = out[n:n + 6 * ns].reshape(ns, 6)
    plant._nl = nl_rows[-18:].copy()
    plant._top_acc = out[-6:]
    return True


def _reference_step(plant: PPHPlant, command_n: np.ndarray) -> dict[str, np.ndarray]:
    """One sample the plain way; the 10 kHz internal-step loop is the shared slow path."""
    st = plant.config.strut
    t0 = plant.sample_index * plant.dt_sample_s
    shaker = plant.shaker.force_n(t0 + plant.dt_internal_s * np.arange(plant.substeps))
    ratio = plant._nl[0:6] / st.stroke_limit_m
    actuator = command_n * (1.0 + ratio * (st.force_constant_linear_per_stroke
                                           - st.force_constant_quadratic_per_stroke * ratio))
    if not _reference_lifted_step(plant, actuator, shaker):
        plant._substep_loop(actuator, shaker)
        plant.fallback_samples += 1
    plant.sample_index += 1
    q = plant.state[:N_DOF]
    relative = q[:6] - q[6:12]
    eddy_noise = plant.eddy._rng.normal(0.0, plant.eddy.config.noise_rms_m, 6)
    return {"accel_m_s2": _reference_accelerometer(plant.accelerometers, plant._acc),
            "eddy_m": plant.eddy.sensing_matrix @ relative + eddy_noise,
            "applied_force_n": actuator, "top_accel_true": plant._top_acc.copy(),
            "relative_pose_true": relative, "stroke_m": plant._nl[0:6].copy()}


def _command(n: int) -> np.ndarray:
    """3 N at 40 Hz, a burst that opens the joints, then a square push onto the stops."""
    sine = np.sin(2 * np.pi * 40 * n / 1000)
    command = 3.0 * sine * np.ones(6)
    if 150 <= n < 180:
        command += 38.0 * sine * np.array([1, -1, 1, -1, 1, -1.0])
    if 350 <= n < 550:
        command += 70.0 * np.sign(np.sin(2 * np.pi * 12 * n / 1000)) * np.ones(6)
    return command


def _run_both(model, tones, noise_rms_n, steps=900):
    """Step an optimised plant and the reference on twins; their samples per field."""
    fast, slow = (PPHPlant(model, shaker=Shaker(tones, noise_rms_n, 100.0, seed=5), seed=6)
                  for _ in range(2))
    got = {f: [] for f in FIELDS}
    want = {f: [] for f in FIELDS}
    for n in range(steps):
        if n == 100:                                  # an external kick, same on both
            for plant in (fast, slow):
                state = plant.state
                state[2] += 3e-5
                plant.set_state(state)
        if n == 700:                                  # runtime shaker changes, same on both
            for plant in (fast, slow):
                plant.shaker.set_tones(tones[:1])
                plant.shaker.noise_rms_n = 2.0 * noise_rms_n
        sample = fast.step(_command(n))
        expected = _reference_step(slow, _command(n))
        for field in FIELDS:
            got[field].append(getattr(sample, field))
            want[field].append(expected[field])
    return ({f: np.array(v) for f, v in got.items()}, {f: np.array(v) for f, v in want.items()},
            fast, slow)


@pytest.mark.parametrize(("nonlinear", "tones", "noise_rms_n"),
                         [(True, TONES, 0.5), (False, TONES, 0.5), (True, DRIFTING, 0.5),
                          (False, DRIFTING, 0.0)])
def test_step_matches_the_plain_reference_implementation(nonlinear, tones, noise_rms_n,
                                                         kernels):
    got, want, fast, slow = _run_both(CFG if nonlinear else CFG.linear(), tones, noise_rms_n)
    assert (fast._kernels is not None) == (kernels == "compiled")
    # Bit-identical on the machine this was written on; the tolerance only leaves room
    # for a BLAS that rounds np.dot and @ differently. The accelerometers are quantised
    # (a 1e-16 difference moves no 16-bit step) and carry the noise: compared exactly.
    np.testing.assert_array_equal(got["accel_m_s2"], want["accel_m_s2"])
    for field in FIELDS[1:]:
        np.testing.assert_allclose(got[field], want[field], rtol=1e-12,
                                   atol=1e-12 * np.abs(want[field]).max(), err_msg=field)
    assert fast.fallback_samples == slow.fallback_samples > 0
    assert fast.accelerometers.clipped_samples == slow.accelerometers.clipped_samples > 0
    assert np.abs(want["stroke_m"]).max() > CFG.strut.stroke_limit_m     # the stops were hit
    # The random streams are in step: the next draws of every generator agree.
    for a, b in ((fast.shaker, slow.shaker), (fast.accelerometers, slow.accelerometers),
                 (fast.eddy, slow.eddy)):
        assert a._rng.random() == b._rng.random()


@pytest.mark.parametrize("tones", [TONES, DRIFTING, []])
@pytest.mark.parametrize(("noise_rms_n", "limit_n"), [(0.0, 100.0), (0.7, 100.0), (3.0, 60.0)])
def test_shaker_force_into_equals_force_n(tones, noise_rms_n, limit_n, kernels):
    fast, slow = (Shaker(tones, noise_rms_n, limit_n, seed=9) for _ in range(2))
    assert (fast._kernels is not None) == (kernels == "compiled")
    out = np.empty(10)
    for start_s in [0.0, 0.001, 0.5, 12.345, 3600.0, 86400.017]:   # up to a day: absolute t
        for k in range(3):
            t0 = start_s + 0.001 * k
            expected = slow.force_n(t0 + 1e-4 * np.arange(10))
            np.testing.assert_array_equal(fast.force_into(t0, 1e-4, out), expected)
    assert fast._rng.random() == slow._rng.random()
