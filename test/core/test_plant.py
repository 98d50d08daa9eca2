"""The simulated PPH is physical: statics, modes, energy, nonlinearity, sensors."""

from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.core.model.config import load_model_config, model_config_from_dict
from hexapod_vibration.core.model.plant import PPHPlant, saturate_commands
from hexapod_vibration.core.model.sensors import AccelerometerBank
from hexapod_vibration.core.model.shaker import Shaker, ShakerTone

MODEL_PATH = Path(__file__).resolve().parents[2] / "config" / "pph_model.yaml"
CFG = load_model_config(MODEL_PATH)
G = CFG.simulation.gravity_m_s2
FS = CFG.simulation.sample_rate_hz


def test_static_deflection_under_gravity_is_what_k_and_m_predict():
    plant = PPHPlant(CFG.linear())
    st, geo = CFG.strut, CFG.geometry
    u_z = geo.unit_vectors[:, 2]
    joint_force = CFG.top_plate.mass_kg * G / (6 * u_z)             # each joint carries 1/6
    spring_force = joint_force + st.moving_mass_kg * G * u_z         # plus its moving part
    q = plant.state[:18]
    stroke = plant.model.stroke_map @ q
    joint = plant.model.joint_map @ q
    np.testing.assert_allclose(stroke, -spring_force / st.suspension_stiffness_n_per_m, rtol=1e-9)
    np.testing.assert_allclose(joint, joint_force / st.joint_stiffness_n_per_m, rtol=1e-9)
    total = (CFG.top_plate.mass_kg + CFG.bottom_plate.mass_kg + 6 * st.moving_mass_kg) * G
    sag = total / (CFG.mounts.count * CFG.mounts.vertical_stiffness_n_per_m)
    assert q[8] == pytest.approx(-sag, rel=1e-9)


def test_free_play_shifts_the_static_contact_by_half_the_clearance():
    plant = PPHPlant(CFG)
    joint = plant.model.joint_map @ plant.state[:18]
    linear_joint = plant.model.joint_map @ PPHPlant(CFG.linear()).state[:18]
    np.testing.assert_allclose(joint - linear_joint, CFG.strut.joint_free_play_m / 2, rtol=1e-6)


def _stiff_mount_config(**strut):
    import yaml

    data = yaml.safe_load(MODEL_PATH.read_text())
    data["mounts"].update(vertical_stiffness_n_per_m=1e10, lateral_stiffness_n_per_m=1e10)
    data["strut"].update(moving_mass_kg=1e-4, joint_stiffness_n_per_m=1e9, **strut)
    return model_config_from_dict(data)


def test_suspension_modes_are_where_the_parameters_put_them():
    cfg = _stiff_mount_config()
    k = cfg.strut.suspension_stiffness_n_per_m
    jtj = np.diag(cfg.geometry.top_jacobian.T @ cfg.geometry.top_jacobian)
    inertia = np.array([cfg.top_plate.mass_kg] * 3 + list(cfg.top_plate.inertia_kg_m2))
    expected = np.sort(np.sqrt(k * jtj / inertia) / (2 * np.pi))
    modes = PPHPlant(cfg).model.modal_frequencies_hz()[:6]
    np.testing.assert_allclose(modes, expected, rtol=2e-3)


def test_simulated_free_response_rings_at_the_model_mode():
    cfg = _stiff_mount_config(suspension_damping_n_s_per_m=2.0)
    plant = PPHPlant(cfg.linear())
    plant.accelerometers.noise_rms_m_s2 = 0.0
    state = plant.state
    state[2] += 1e-4                                  # lift the top plate by 0.1 mm
    plant.set_state(state)
    z = np.array([plant.step(np.zeros(6)).relative_pose_true[2] for _ in range(4000)])
    spectrum = np.abs(np.fft.rfft((z - z.mean()) * np.hanning(z.size), 8 * z.size))
    peak_hz = np.fft.rfftfreq(8 * z.size, 1 / FS)[np.argmax(spectrum)]
    k = cfg.strut.suspension_stiffness_n_per_m
    assert peak_hz == pytest.approx(np.sqrt(2 * k / cfg.top_plate.mass_kg) / (2 * np.pi), rel=0.01)


@pytest.mark.parametrize("nonlinear", [False, True])
def test_energy_is_not_created_with_actuators_and_shaker_off(nonlinear):
    plant = PPHPlant(CFG if nonlinear else CFG.linear())
    state = plant.state
    state[2] += 6e-5                     # 60 um: the joints open (free-play crossings)
    state[18 + 3] = 0.02                 # and a tilt rate (rad/s)
    plant.set_state(state)
    energy = [plant.mechanical_energy_j()]
    for _ in range(2000):
        plant.step(np.zeros(6))
        energy.append(plant.mechanical_energy_j())
    energy = np.array(energy) - energy[0]
    assert np.max(energy) < 1e-9                       # never above the initial energy
    assert energy[-1] < 0.5 * energy.min()             # and it dissipates
    if nonlinear:
        assert plant.fallback_samples > 0              # the free-play path was exercised


def test_undamped_linear_plant_conserves_energy():
    import yaml

    data = yaml.safe_load(MODEL_PATH.read_text())
    for key in ("suspension_damping_n_s_per_m", "joint_damping_n_s_per_m"):
        data["strut"][key] = 1e-12
    data["mounts"].update(vertical_damping_n_s_per_m=1e-12, lateral_damping_n_s_per_m=1e-12)
    plant = PPHPlant(model_config_from_dict(data).linear())
    state = plant.state
    state[2] += 1e-4
    plant.set_state(state)
    e0 = plant.mechanical_energy_j()
    for _ in range(1000):
        plant.step(np.zeros(6))
    assert plant.mechanical_energy_j() == pytest.approx(e0, rel=1e-6)


def _z_accel_response(cfg, amplitude_n, samples=4000):
    plant = PPHPlant(cfg, seed=3)
    accel = np.array([plant.step(amplitude_n * np.sin(2 * np.pi * 40 * n / FS) * np.ones(6))
                      .accel_m_s2 for n in range(samples)])
    return CFG.geometry.platform_from_struts(accel[samples // 2:])[:, 2]


def test_40hz_into_all_actuators_is_distorted_only_with_nonlinearities():
    from hexapod_vibration.core.spectrum import harmonic_distortion

    """Paper Fig. 4: the ball joints unload and cross their free-play."""
    nonlinear = harmonic_distortion(_z_accel_response(CFG, 38.0), FS, 40.0, n_harmonics=5)
    linear = harmonic_distortion(_z_accel_response(CFG.linear(), 38.0), FS, 40.0, n_harmonics=5)
    assert nonlinear["thd_percent"] > 5.0
    assert linear["thd_percent"] < 0.1


def test_lifted_sample_equals_the_internal_step_loop():
    def run(force_loop):
        plant = PPHPlant(CFG, shaker=Shaker([ShakerTone(40.0, 20.0)], seed=1), seed=2)
        if force_loop:
            plant._lifted_step = lambda *_: False
        return np.array([plant.step(30 * np.sin(0.25 * n) * np.ones(6)).top_accel_true
                         for n in range(600)]), plant.fallback_samples

    lifted, fallbacks = run(False)
    looped, _ = run(True)
    assert 0 < fallbacks < 600          # both paths were used in the lifted run
    np.testing.assert_allclose(lifted, looped, atol=1e-9)


def test_set_state_continues_exactly_as_the_plant_that_stepped_there():
    """After set_state the next samples use its strokes for the voice-coil force constant."""
    command = -60.0 * np.ones(6)                    # ~-3.5 mm stroke: force constant ~0.9
    stepped, moved = PPHPlant(CFG, seed=1), PPHPlant(CFG, seed=2)
    for _ in range(40):
        stepped.step(command)
    for _ in range(5):                              # warm caches from a different state
        moved.step(np.zeros(6))
    moved.set_state(stepped.state)
    for _ in range(3):
        want, got = stepped.step(command), moved.step(command)
        np.testing.assert_allclose(got.applied_force_n, want.applied_force_n, rtol=1e-12)
        np.testing.assert_allclose(got.stroke_m, want.stroke_m, rtol=1e-12)
        np.testing.assert_allclose(moved.state, stepped.state, rtol=1e-12,
                                   atol=1e-12 * np.abs(stepped.state).max())
        assert np.all(want.applied_force_n / command < 0.95)


def test_set_state_redoes_the_start_of_sample_contact_regime_test():
    """A plant held in the contact regime must not carry that decision to a new state."""
    warm, looped = PPHPlant(CFG), PPHPlant(CFG)
    looped._lifted_step = lambda *_: False          # reference: internal steps one by one
    for _ in range(5):
        warm.step(np.zeros(6))
    assert warm._start_in_regime                    # joints settled in contact
    joint_map, state = warm.model.joint_map, warm.state
    half_play = 0.5 * CFG.strut.joint_free_play_m
    # joints just inside the clearance, closing it again within the first internal step
    state[:18] += np.linalg.lstsq(joint_map, 0.9 * half_play - joint_map @ state[:18],
                                  rcond=None)[0]
    state[18:] += np.linalg.lstsq(joint_map, 0.05 * np.ones(6), rcond=None)[0]
    for plant in (warm, looped):
        plant.set_state(state)
        plant.step(np.zeros(6))
    np.testing.assert_allclose(warm.state, looped.state, rtol=1e-12,
                               atol=1e-12 * np.abs(looped.state).max())


def test_accelerometers_clip_at_2g_and_quantise_to_16_bits():
    bank = AccelerometerBank(CFG.accelerometer, 10000.0, 1000.0, seed=0)
    levels_g = np.array([-3.0, -1.0, 0.0, 0.5, 1.9, 3.0])
    bank.settle(levels_g * G)
    for _ in range(50):
        out = bank.sample(np.tile(levels_g * G, (10, 1)))
    lsb = 4 * G / 2**16
    assert out[0] == pytest.approx(-2 * G)
    assert out[-1] == pytest.approx(2 * G - lsb)
    np.testing.assert_allclose(out[1:5], levels_g[1:5] * G, atol=3 * lsb + 1e-4)
    np.testing.assert_allclose(out / lsb, np.round(out / lsb), atol=1e-9)
    assert bank.clipped_samples == 50


def test_accelerometers_report_gravity_along_each_strut_at_rest():
    plant = PPHPlant(CFG)
    accel = np.mean([plant.step(np.zeros(6)).accel_m_s2 for _ in range(200)], axis=0)
    np.testing.assert_allclose(accel, G * CFG.geometry.unit_vectors[:, 2], atol=2e-3)


def test_eddy_sensors_recover_the_relative_pose():
    plant = PPHPlant(CFG)
    sample = plant.step(np.array([5.0, -5.0, 5.0, -5.0, 5.0, -5.0]))
    pose = plant.eddy.pose(sample.eddy_m)
    np.testing.assert_allclose(pose, sample.relative_pose_true, atol=1e-6)


def test_actuator_limits_dynamic_then_static():
    st = CFG.strut
    applied = saturate_commands(np.array([100.0, -100.0, 10, 0, 0, 0]),
                                np.array([50.0, -50.0, 65, 0, 0, 0]), st)
    np.testing.assert_allclose(applied, [70.0, -70.0, 70.0, 0, 0, 0])
    applied = saturate_commands(np.array([100.0, 0, 0, 0, 0, 0]), np.zeros(6), st)
    assert applied[0] == st.force_limit_dynamic_n


def test_model_config_rejects_bad_values_clearly():
    import yaml

    data = yaml.safe_load(MODEL_PATH.read_text())
    data["strut"]["suspension_stiffness_n_per_m"] = -1.0
    with pytest.raises(ValueError, match="suspension_stiffness_n_per_m"):
        model_config_from_dict(data)
    with pytest.raises(ValueError, match="unknown key"):
        load_model_config(MODEL_PATH, overrides={"strut": {"bogus_m": 1.0}})


def test_shaker_can_push_on_the_top_plate_and_bad_bodies_are_refused():
    from hexapod_vibration.core.model.plant import IN_SHAKER, LinearHexapodModel

    top = load_model_config(MODEL_PATH, {"shaker": {"mounted_on": "top_plate"}})
    for config, pushed, free in ((CFG, slice(6, 12), slice(0, 6)),
                                 (top, slice(0, 6), slice(6, 12))):
        column = LinearHexapodModel(config).input_map[:, IN_SHAKER]
        assert column[pushed][2] == 1.0 and not np.any(column[free])
    with pytest.raises(ValueError, match="mounted_on"):
        load_model_config(MODEL_PATH, {"shaker": {"mounted_on": "table"}})


def test_a_model_file_without_the_shaker_body_keeps_the_bottom_plate():
    import yaml

    data = yaml.safe_load(MODEL_PATH.read_text())
    del data["shaker"]["mounted_on"]
    assert model_config_from_dict(data).shaker.mounted_on == "bottom_plate"
    del data["shaker"]["force_limit_n"]
    with pytest.raises(ValueError, match="force_limit_n"):
        model_config_from_dict(data)
