"""The rotating-machine source: speed profile, exact phase, speed-squared amplitudes, validation."""

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from hexapod_vibration.core.model.rotor import Rotor, rotor_or_none
from hexapod_vibration.core.model.shaker import Shaker, tones_from_arrays
from hexapod_vibration.core.sim.scenario import RotorSettings, scenario_from_dict

SPIN_UP = dict(orders=[1.0, 2.0, 3.0], amplitudes_n=[10.0, 4.0, 2.0], reference_speed_hz=50.0,
               profile_time_s=[2.0, 22.0], profile_speed_hz=[30.0, 50.0])


def test_speed_is_piecewise_linear_and_held_outside_the_profile():
    rotor = Rotor(**SPIN_UP)
    t = np.array([0.0, 1.0, 2.0, 7.0, 12.0, 22.0, 30.0])
    assert rotor.speed_hz(t) == pytest.approx([30.0, 30.0, 30.0, 35.0, 40.0, 50.0, 50.0])
    assert rotor.speed_hz(t) == pytest.approx(np.interp(t, [2.0, 22.0], [30.0, 50.0]))


def test_revolutions_match_a_numerical_integral_of_the_speed():
    rotor = Rotor([1.0], [1.0], 40.0, [0.5, 3.0, 4.0, 6.0], [10.0, 60.0, 60.0, 5.0])
    t = np.linspace(0.0, 8.0, 800_001)
    numerical = cumulative_trapezoid(rotor.speed_hz(t), t, initial=0.0)
    assert np.max(np.abs(rotor.revolutions(t) - numerical)) < 1e-6


def test_instantaneous_frequency_of_each_order_is_order_times_speed():
    rotor = Rotor(**SPIN_UP)
    t = np.linspace(0.0, 25.0, 250_001)
    phase = 2.0 * np.pi * rotor.revolutions(t)[:, None] * rotor.orders
    measured = np.gradient(phase, t, axis=0) / (2.0 * np.pi)
    smooth = np.all(np.abs(t[:, None] - [2.0, 22.0]) > 2e-4, axis=1)   # off the profile's kinks
    assert np.max(np.abs(measured - rotor.frequencies_hz(t))[smooth]) < 1e-6
    assert rotor.frequencies_hz(12.0) == pytest.approx([40.0, 80.0, 120.0])


def test_amplitudes_scale_with_speed_squared_at_the_order_frequencies():
    fs, seconds = 1000.0, 10.0
    t = np.arange(int(fs * seconds)) / fs
    for speed in (50.0, 25.0):
        rotor = Rotor([1.0, 2.0], [8.0, 2.0], 50.0, [0.0], [speed])
        spectrum = np.abs(np.fft.rfft(rotor.force_n(t))) * 2.0 / t.size
        freqs = np.fft.rfftfreq(t.size, 1.0 / fs)
        scale = (speed / 50.0) ** 2
        for order, amplitude in zip(rotor.orders, rotor.amplitudes_n, strict=True):
            line = np.argmin(np.abs(freqs - order * speed))
            assert spectrum[line] == pytest.approx(amplitude * scale, rel=1e-9)


def test_force_matches_the_closed_form_during_a_linear_ramp():
    rotor = Rotor([1.5], [3.0], 40.0, [0.0, 10.0], [20.0, 40.0], phases_rad=[0.4])
    t = np.linspace(0.0, 10.0, 1001)
    speed = 20.0 + 2.0 * t
    expected = 3.0 * (speed / 40.0) ** 2 * np.sin(2 * np.pi * 1.5 * (20 * t + t**2) + 0.4)
    assert rotor.force_n(t) == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("changes, reason", [
    (dict(orders=[1.0, 2.0]), "same length"),
    (dict(orders=[0.0, 2.0, 3.0]), "orders must be > 0"),
    (dict(amplitudes_n=[1.0, -1.0, 1.0]), ">= 0 N"),
    (dict(reference_speed_hz=0.0), "reference speed"),
    (dict(profile_time_s=[5.0, 5.0]), "strictly increasing"),
    (dict(profile_time_s=[-1.0, 5.0]), "strictly increasing"),
    (dict(profile_time_s=[1.0]), "same number"),
    (dict(profile_time_s=[], profile_speed_hz=[]), "at least one"),
    (dict(profile_speed_hz=[30.0, -1.0]), "speeds must be >= 0"),
    (dict(profile_speed_hz=[30.0, float("nan")]), "finite"),
    (dict(orders=[], amplitudes_n=[]), "at least one"),
])
def test_bad_settings_are_refused_with_the_reason(changes, reason):
    with pytest.raises(ValueError, match=reason):
        Rotor(**{**SPIN_UP, **changes})


def test_no_orders_means_no_rotor():
    assert rotor_or_none([], [], 50.0, [0.0], [50.0]) is None
    assert RotorSettings().rotor() is None


def test_the_shaker_adds_the_rotor_after_its_own_clipping_in_both_paths():
    tones = tones_from_arrays([40.0, 80.0], [60.0, 30.0])
    drifting = tones_from_arrays([40.0], [60.0], drift_hz=1.0, drift_period_s=5.0)
    rotor = Rotor(**SPIN_UP)
    for shaker_tones in (tones, drifting):
        plain, with_rotor, direct = (Shaker(shaker_tones, 0.5, 70.0, seed=3, rotor=r)
                                     for r in (None, rotor, rotor))
        start, step, n = 5.0123, 1e-4, 10
        times = start + step * np.arange(n)
        out = np.empty(n)
        with_rotor.force_into(start, step, out)
        expected = plain.force_n(times) + rotor.force_n(times)
        assert out == pytest.approx(expected, abs=1e-12)
        assert direct.force_n(times) == pytest.approx(expected, abs=1e-12)


def test_without_a_rotor_the_shaker_force_is_unchanged_bit_for_bit():
    tones = tones_from_arrays([40.0, 80.0, 120.0], [80.0, 16.0, 12.0])
    a, b = Shaker(tones, 0.5, 100.0, seed=7), Shaker(tones, 0.5, 100.0, seed=7, rotor=None)
    out_a, out_b = np.empty(10), np.empty(10)
    for k in range(3):
        a.force_into(k * 1e-3, 1e-4, out_a)
        b.force_into(k * 1e-3, 1e-4, out_b)
        assert np.array_equal(out_a, out_b)


def test_disturbance_frequencies_list_shaker_tones_with_drift_then_rotor_orders():
    drifting = tones_from_arrays([40.0, 60.0], [1.0, 1.0], drift_hz=1.0, drift_period_s=20.0)
    shaker = Shaker(drifting, rotor=Rotor(**SPIN_UP))
    assert shaker.frequencies_hz(5.0) == pytest.approx([41.0, 61.0, 33.0, 66.0, 99.0])
    assert shaker.frequencies_hz(np.array([0.0, 12.0])).shape == (2, 5)
    assert Shaker(drifting).frequencies_hz(15.0) == pytest.approx([39.0, 59.0])
    silent = tones_from_arrays([40.0, 60.0], [0.0, 1.0])
    quiet_order = Rotor([1.0, 2.0], [0.0, 3.0], 50.0, [0.0], [30.0])
    assert Shaker(silent, rotor=quiet_order).frequencies_hz(1.0) == pytest.approx([60.0, 60.0])


def test_scenario_rotor_section_builds_the_rotor_and_refuses_bad_keys():
    base = {"name": "spin", "duration_s": 4.0, "control_on_s": 2.0, "window_s": 1.0}
    scenario = scenario_from_dict({**base, "rotor": {**SPIN_UP, "tachometer": True}})
    assert scenario.rotor.tachometer is True
    assert scenario.rotor.rotor().frequencies_hz(22.0) == pytest.approx([50.0, 100.0, 150.0])
    assert scenario_from_dict(base).rotor.rotor() is None
    with pytest.raises(TypeError):
        scenario_from_dict({**base, "rotor": {**SPIN_UP, "order": [1.0]}})
    with pytest.raises(ValueError, match="tachometer"):
        scenario_from_dict({**base, "rotor": {**SPIN_UP, "tachometer": "yes"}})
    with pytest.raises(ValueError, match="strictly increasing"):
        scenario_from_dict({**base, "rotor": {**SPIN_UP, "profile_time_s": [3.0, 1.0]}})


def test_core_loop_puts_the_scenario_rotor_on_the_plant():
    from hexapod_vibration.core.model.config import load_model_config
    from hexapod_vibration.core.sim.closed_loop import CoreLoop
    from hexapod_vibration.paths import config_path

    base = {"name": "spin", "duration_s": 0.05, "control_on_s": 0.05, "window_s": 0.01}
    scenario = scenario_from_dict({**base, "rotor": SPIN_UP})
    loop = CoreLoop(load_model_config(config_path("pph_model.yaml")), scenario)
    assert loop.plant.shaker.rotor is loop.rotor
    record = loop.run()
    quiet = CoreLoop(load_model_config(config_path("pph_model.yaml")),
                     scenario_from_dict(base)).run()
    # Same seeds, and the rotor draws no noise: the difference is the rotor's response alone.
    difference = record.accel_m_s2 - quiet.accel_m_s2
    assert np.max(np.abs(difference)) > 0.05
