"""Predicted sensitivity of the adapting canceller: closed form, simulation, stability."""

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from hexapod_vibration.core.control import adaptation as ad
from hexapod_vibration.core.control import sensitivity as sen
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from linear_plants import FS, frequency_response, resonance_bank, simulate  # noqa: E402

TONES = [39.0, 40.0]


def _coupled_plant(n=3, seed=3, spread=0.5):
    a, b, c = resonance_bank([30.0, 55.0, 90.0][:n], 0.05, 1.0)
    mix = np.eye(n) + spread * np.random.default_rng(seed).normal(size=(n, n))
    return a, b @ mix, c


def _exact(plant):
    return lambda f: frequency_response(plant, f)


def test_closed_form_equals_the_state_space_of_the_canceller():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(2, 3, 3)) + 1j * rng.normal(size=(2, 3, 3))
    f = np.array([0.0, 1.0, 39.7, 40.3, 123.0, 400.0, 500.0])
    k = sen.canceller_frequency_response([40.0, 80.0], FS, p, 0.01, f)
    a, b, c, d = ad.canceller_state_space([40.0, 80.0], FS, p, 0.01)
    eye = np.eye(a.shape[0])
    k_ss = np.stack([c @ np.linalg.solve(np.exp(2j * np.pi * x / FS) * eye - a, b) + d
                     for x in f])
    assert np.max(np.abs(k - k_ss)) < 1e-12 * np.max(np.abs(k_ss))


def test_closed_form_with_the_rate_integrator_is_the_cancellers_impulse_response():
    """Type-2 update: h_n = Re{mu P p^n (1 + kappa (n + 1))}, and K is its z-transform."""
    p, mu, ratio, tone = np.array([[[-1.5 + 0.7j]]]), 0.01, 0.5, 40.0
    anc = AdaptiveNotchCanceller(1, [tone], FS, mu, p)
    anc.set_integral_ratio(ratio)
    n = np.arange(4000)
    h = np.array([anc.step(np.array([1.0 if k == 0 else 0.0]))[0] for k in n])
    pole = np.exp(2j * np.pi * tone / FS)
    expected = (mu * p[0, 0, 0] * pole ** n * (1.0 + ratio * mu * (n + 1))).real
    assert np.max(np.abs(h - expected)) < 1e-12
    radius, f = 1.01, np.array([3.0, 39.5, 40.2, 120.0])
    z = radius * np.exp(2j * np.pi * f / FS)
    k_sum = np.array([np.sum(h * zz ** -n) for zz in z])
    k = sen.canceller_frequency_response([tone], FS, p, mu, f, radius, integral_ratio=ratio)
    assert np.max(np.abs(k[:, 0, 0] - k_sum)) < 1e-9 * np.max(np.abs(k_sum))
    first = sen.canceller_frequency_response([tone], FS, p, mu, f, radius)
    assert np.max(np.abs(k - first)) > 0.1 * np.max(np.abs(first))


def test_per_tone_rates_fold_into_the_coefficients():
    rng = np.random.default_rng(1)
    p = rng.normal(size=(2, 2, 2)) + 1j * rng.normal(size=(2, 2, 2))
    f = np.linspace(30.0, 50.0, 41)
    folded = sen.per_tone_coefficients(p, 0.004, [0.001, 0.004])
    k_folded = sen.canceller_frequency_response([39.0, 40.0], FS, folded, 0.004, f)
    k_rates = sen.canceller_frequency_response([39.0, 40.0], FS, p, [0.001, 0.004], f)
    assert np.allclose(k_folded, k_rates, rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="mu must be > 0"):
        sen.per_tone_coefficients(p, 0.0, [0.001, 0.004])
    with pytest.raises(ValueError, match="per-tone rates"):
        sen.per_tone_coefficients(p, 0.004, [0.001])


def test_sensitivity_is_zero_at_the_tones_and_one_far_away():
    plant = _coupled_plant()
    g = _exact(plant)
    p = ad.normalized_coefficients(g(TONES), "centralized")
    pred = sen.predict_sensitivity(g, TONES, FS, p, 0.002, frequencies_hz=[39.0, 40.0, 300.0])
    assert np.all(pred.sigma_max[:2] < 1e-6)
    assert abs(pred.sigma_max[2] - 1.0) < 0.01
    assert pred.stable


@pytest.mark.parametrize("mode", ["centralized", "decentralized"])
def test_prediction_matches_the_simulated_loop(mode):
    """Same noise with and without the canceller: the ratio of the spectra is |S|^2.

    Checked per strut (the error e_i with control over e_i without, noise in every
    channel) within +-5 Hz of the tones, through the Welch window's kernel.
    """
    plant = _coupled_plant()
    g = _exact(plant)
    p = ad.normalized_coefficients(g(TONES), mode)
    n, mu = 200_000, 0.002
    dist = 0.01 * np.random.default_rng(4).normal(size=(n, 3))
    errors = simulate(plant, AdaptiveNotchCanceller(3, TONES, FS, mu, p), dist)
    f, p_on = signal.welch(errors[20_000:], FS, window="hann", nperseg=4000, axis=0)
    _, p_off = signal.welch(dist[20_000:], FS, window="hann", nperseg=4000, axis=0)
    measured = 10 * np.log10(p_on / p_off)                        # (F, 3)
    grid = sen.prediction_grid(TONES, FS, mu)
    s = sen.sensitivity_matrix(g(grid), sen.canceller_frequency_response(TONES, FS, p, mu,
                                                                          grid))
    power = np.sum(np.abs(s) ** 2, axis=2)                        # white, equal noise
    near = np.flatnonzero((f > 34.0) & (f < 45.0))
    win = signal.get_window("hann", 4000)
    expected = np.empty((near.size, 3))
    for m, k in enumerate(near):
        sel = np.abs(grid - f[k]) < 3.0
        kern = np.abs(np.exp(-2j * np.pi * np.outer((grid[sel] - f[k]) / FS,
                                                    np.arange(4000))) @ win) ** 2
        kern *= np.gradient(grid[sel])
        expected[m] = 10 * np.log10(kern @ power[sel] / kern.sum())
    error = measured[near] - expected
    # 89 Welch averages: about 0.3 dB of scatter per bin
    assert np.sqrt(np.mean(error ** 2)) < 0.3
    assert np.max(np.abs(error)) < 1.0
    assert np.min(expected) < -6.0                                # the notches are resolved
    if mode == "decentralized":                                   # and the coupling's rise
        assert np.max(expected) > 0.3


def test_nyquist_test_agrees_with_the_exact_bound():
    for plant, tones in ((resonance_bank(60.0, 0.02, 1.0), [40.0]),
                         (resonance_bank(60.0, 0.02, 1.0), [100.0]),
                         (_coupled_plant(), TONES)):
        g = _exact(plant)
        p = ad.normalized_coefficients(g(tones), "decentralized")
        exact = ad.exact_mu_bound(plant, tones, FS, p)
        assert sen.closed_loop_is_stable(g, tones, FS, p, 0.95 * exact)
        assert not sen.closed_loop_is_stable(g, tones, FS, p, 1.05 * exact)
        limit = sen.stable_mu_limit(g, tones, FS, p)
        assert abs(limit / exact - 1.0) < 0.02


def test_largest_rise_is_where_the_weight_loop_turns():
    """A coefficient off by 60 deg: |S| peaks at 1/cos(60 deg) (+6 dB) beside the notch."""
    plant = resonance_bank(300.0, 0.5, 1.0)                       # flat near 40 Hz
    g = _exact(plant)
    p = ad.normalized_coefficients(g([40.0]), "centralized") * np.exp(1j * np.pi / 3)
    for mu in (0.0005, 0.002):
        rise, at_hz = sen.predict_sensitivity(g, [40.0], FS, p, mu).largest_rise("sigma_max")
        assert abs(rise - 20 * np.log10(2.0)) < 0.3
        assert 0.0 < abs(at_hz - 40.0) < 4 * mu * FS / (2 * np.pi)


def test_output_view_weights_the_disturbance():
    plant = _coupled_plant()
    g = _exact(plant)
    p = ad.normalized_coefficients(g(TONES), "decentralized")
    f = np.array([38.5, 41.0])
    s = sen.sensitivity_matrix(g(f), sen.canceller_frequency_response(TONES, FS, p, 0.002, f))
    c = np.array([1.0, 0.0, 0.0])
    one_channel = np.zeros((2, 3, 3))
    one_channel[:, 0, 0] = 1.0
    assert np.allclose(sen.output_sensitivity(s, c, one_channel), np.abs(s[:, 0, 0]))
    flat = sen.output_sensitivity(s, c)
    assert np.allclose(flat, np.linalg.norm(s[:, 0, :], axis=1))
