"""Tests of the Adaptive Notch Canceller on linear discrete-time test plants."""

import tracemalloc

import numpy as np
import pytest
from linear_plants import frequency_response, resonance_bank, simulate

from hexapod_vibration.core import spectrum as sp
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

FS = 1000.0


# ----------------------------------------------------------------------------- test plant
def resonant_plant(f_res_hz, zeta=0.2, gain=0.1, coupling=0.0, seed=0):
    """(A, B, C) at FS: static coupling K, then per-channel resonance g w^2/(s^2+2zws+w^2).

    ZOH discretisation of a strictly proper system: a command of sample n reaches the
    output from sample n+1 on, as in docs/architecture.md.
    """
    f_res_hz = np.atleast_1d(f_res_hz)
    n = f_res_hz.size
    rng = np.random.default_rng(seed)
    k = np.eye(n) + coupling * rng.uniform(-1, 1, (n, n)) * (1 - np.eye(n))
    a, b, c = resonance_bank(f_res_hz, zeta, gain)
    return a, b @ k, c


def tone_phasor(x, freq_hz, n0=0):
    """Least-squares phasor (a - j b) of a tone in x (time index n0 + k)."""
    n = n0 + np.arange(x.shape[0])
    reg = np.column_stack([np.cos(2 * np.pi * freq_hz * n / FS),
                           np.sin(2 * np.pi * freq_hz * n / FS), np.ones(n.size)])
    coef, *_ = np.linalg.lstsq(reg, x, rcond=None)
    return coef[0] - 1j * coef[1]


# ----------------------------------------------------------------------------- paper loop
def test_siso_matched_converges_to_eq21_and_to_noise_floor():
    """Raw paper algorithm (P = 1) on a SISO plant with cos(beta) < 0."""
    f, d_amp, gamma, sigma = 40.0, 0.3, 0.7, 3e-3
    plant = resonant_plant([25.0])
    g = frequency_response(plant, f)[0, 0, 0]
    alpha, beta = abs(g), np.angle(g)
    assert np.cos(beta) < -0.9                          # tone above the 25 Hz resonance
    mu = 0.01 / (alpha * abs(np.cos(beta)))            # (mu/2) alpha |cos b| = 0.005/sample
    n = np.arange(int(14 * FS))
    rng = np.random.default_rng(1)
    dist = (d_amp * np.cos(2 * np.pi * f * n / FS + gamma)
            + sigma * rng.standard_normal(n.size))[:, None]
    anc = AdaptiveNotchCanceller(1, [f], FS, mu)
    w_hist = np.empty(n.size, dtype=complex)

    def record(k):
        w_hist[k] = anc.weights[0, 0]

    err = simulate(plant, anc, dist, record)[:, 0]
    # eq. (21) in this package's convention W = a - j b: W* = -(D/alpha) e^{j(gamma - beta)}
    a_opt = -(d_amp / alpha) * np.cos(gamma - beta)
    b_opt = +(d_amp / alpha) * np.sin(gamma - beta)    # (the paper prints -; see report)
    w_mean = w_hist[4000:].mean()
    assert abs(w_mean - (a_opt - 1j * b_opt)) / abs(a_opt - 1j * b_opt) < 0.01
    assert abs(w_mean.real - a_opt) < 0.01 * abs(w_mean)
    assert abs(-w_mean.imag - b_opt) < 0.01 * abs(w_mean)
    # the tone is down to the noise floor: PSD at the tone no higher than the local floor
    before = sp.tone_levels_db(dist[:, 0], FS, [f])[0]
    after_x = err[4000:]
    freqs, psd = sp.power_spectral_density(after_x, FS)
    at_tone = psd[np.abs(freqs - f) <= 0.4].mean()
    floor = np.median(psd[(np.abs(freqs - f) > 0.5) & (np.abs(freqs - f) < 3.0)])
    assert 10 * np.log10(at_tone / floor) < 1.0
    assert sp.tone_levels_db(after_x, FS, [f])[0] < min(before - 50.0,
                                                        sp.noise_floor_db(after_x, FS, f))


def test_frequency_mismatch_weights_rotate_and_error_stays_bounded():
    f_ctrl, df, d_amp = 40.0, 0.5, 0.3
    plant = resonant_plant([60.0])
    g = frequency_response(plant, f_ctrl)[0]
    anc = AdaptiveNotchCanceller(1, [f_ctrl], FS, 0.05, -2.0 / g[None])
    n = np.arange(int(5 * FS))
    dist = (d_amp * np.cos(2 * np.pi * (f_ctrl + df) * n / FS + 0.2))[:, None]
    w_hist = np.empty(n.size, dtype=complex)

    def record(k):
        w_hist[k] = anc.weights[0, 0]

    err = simulate(plant, anc, dist, record)[:, 0]
    late = slice(3000, None)
    slope = np.polyfit(n[late], np.unwrap(np.angle(w_hist[late])), 1)[0]
    expected = 2 * np.pi * df / FS
    assert abs(slope - expected) / expected < 0.05
    assert np.all(np.isfinite(err)) and np.max(np.abs(err[late])) < d_amp
    assert np.sqrt(np.mean(err[late] ** 2)) < 0.5 * d_amp / np.sqrt(2)


def _reference_canceller(errors, freqs, mu, p):
    """Explicit loops: W += mu P e e^{-j phi}; u = sum Re{W e^{j phi}}; phi += w."""
    t, c = p.shape[0], p.shape[1]
    w = np.zeros((t, c), dtype=complex)
    out = np.zeros_like(errors)
    for n, e in enumerate(errors):
        for k in range(t):
            phi = 2 * np.pi * freqs[k] * n / FS
            for i in range(c):
                w[k, i] += mu * sum(p[k, i, j] * e[j] for j in range(c)) * np.exp(-1j * phi)
                out[n, i] += (w[k, i] * np.exp(1j * phi)).real
    return out


def test_paper_eqs_6_to_9_and_both_update_paths_match_reference():
    rng = np.random.default_rng(4)
    freqs, mu, c = [40.0, 80.0, 123.0], 0.01, 3
    errors = rng.standard_normal((200, c))
    p_full = rng.standard_normal((3, c, c)) + 1j * rng.standard_normal((3, c, c))
    p_diag = np.stack([np.diag(np.diag(m)) for m in p_full])
    for p in (p_full, p_diag):
        anc = AdaptiveNotchCanceller(c, freqs, FS, mu, p)
        assert anc.is_diagonal == (p is p_diag)
        got = np.array([anc.step(e) for e in errors])
        assert np.allclose(got, _reference_canceller(errors, freqs, mu, p), atol=1e-12)
    # P = I is the paper: a += mu e cos(wn), b += mu e sin(wn), x = a cos(wn) + b sin(wn)
    anc = AdaptiveNotchCanceller(1, [40.0], FS, mu)
    a = b = 0.0
    for n, e in enumerate(errors[:, 0]):
        wn = 2 * np.pi * 40.0 * n / FS
        a, b = a + mu * e * np.cos(wn), b + mu * e * np.sin(wn)
        assert anc.step(np.array([e]))[0] == pytest.approx(a * np.cos(wn) + b * np.sin(wn),
                                                          abs=1e-12)
    assert anc.weights[0, 0] == pytest.approx(a - 1j * b)


# ----------------------------------------------------------------------------- bumpless
def _run_open_loop(anc, n, changes):
    out = np.empty(n)
    for k in range(n):
        if k in changes:
            changes[k]()
        out[k] = anc.step(np.zeros(1))[0]
    return out


def _max_step(u):
    return np.max(np.abs(np.diff(u)))


def test_frequency_change_is_bumpless():
    anc = AdaptiveNotchCanceller(1, [40.0, 80.0], FS, 0.0)
    anc.set_weights(np.array([[1.0 - 0.5j], [0.3 + 0.2j]]))
    u = _run_open_loop(anc, 800, {400: lambda: anc.set_tone_frequencies([80.0, 97.0])})
    normal = _max_step(u[100:400])
    assert _max_step(u[399:]) <= normal
    # the kept 80 Hz tone keeps its weight; the new one starts at 0 and does not adapt
    assert np.allclose(anc.weights[:, 0], [0.3 + 0.2j, 0.0])
    assert anc.adapting.tolist() == [True, False]
    # after the fade only the 80 Hz tone remains, continuous with its earlier output
    n = np.arange(800)
    expected = ((0.3 + 0.2j) * np.exp(2j * np.pi * 80.0 * n[500:] / FS)).real
    assert np.allclose(u[500:], expected, atol=1e-12)


def test_enable_toggle_is_bumpless_and_freezes_adaptation():
    anc = AdaptiveNotchCanceller(1, [40.0], FS, 0.05)
    anc.set_weights(np.array([[0.8 + 0.4j]]))
    changes = {300: lambda: anc.set_enabled(False, ramp_samples=50),
               600: lambda: anc.set_enabled(True, ramp_samples=50)}
    u = np.empty(900)
    for k in range(900):
        if k in changes:
            changes[k]()
        w_before = anc.weights
        u[k] = anc.step(np.array([0.5]))[0]      # a non-zero error would adapt the weights
        if 300 <= k < 600:
            assert np.array_equal(anc.weights, w_before)
    normal = _max_step(u[100:300])
    assert _max_step(u[299:700]) <= normal * (1 + 1e-9)
    assert np.all(u[350:600] == 0.0) and anc.output_gain == 1.0 and anc.enabled


def test_new_tone_adapts_only_with_coefficients_and_reset():
    anc = AdaptiveNotchCanceller(2, [40.0], FS, 0.01)
    anc.set_tone_frequencies([40.0, 90.0])
    assert anc.adapting.tolist() == [True, False]
    for _ in range(50):
        anc.step(np.array([0.3, -0.2]))
    assert np.all(anc.weights[1] == 0) and np.any(anc.weights[0] != 0)
    anc.set_coefficients(np.ones((2, 2), dtype=complex))         # (T, C) diagonal form
    assert anc.adapting.tolist() == [True, True] and anc.is_diagonal
    anc.step(np.array([0.3, -0.2]))
    assert np.all(anc.weights[1] != 0)
    anc.reset_weights()
    assert np.all(anc.weights == 0)
    assert np.all(anc.phases_rad >= 0) and np.all(anc.phases_rad < 2 * np.pi)


# ----------------------------------------------------------------------------- validation
def _snapshot(anc):
    return (anc.weights, anc.tone_frequencies_hz, anc.mu, anc.coefficients, anc.adapting,
            anc.phases_rad, anc.enabled)


def _same(s1, s2):
    return all(np.array_equal(a, b) for a, b in zip(s1, s2, strict=True))


@pytest.mark.parametrize("bad_call", [
    lambda a: a.set_mu(-0.1),
    lambda a: a.set_mu(float("nan")),
    lambda a: a.set_mu("fast"),
    lambda a: a.set_tone_frequencies([40.0, 500.0]),
    lambda a: a.set_tone_frequencies([0.0]),
    lambda a: a.set_tone_frequencies([-5.0]),
    lambda a: a.set_tone_frequencies([40.0, 40.0]),
    lambda a: a.set_tone_frequencies([float("inf")]),
    lambda a: a.set_tone_frequencies([50.0, 60.0], coefficients=np.ones((3, 2, 2))),
    lambda a: a.set_coefficients(np.ones((2, 3, 3))),
    lambda a: a.set_coefficients(np.full((2, 2, 2), np.nan)),
    lambda a: a.set_enabled(False, ramp_samples=-1),
    lambda a: a.set_weights(np.ones((3, 2))),
    lambda a: a.step(np.ones(3)),
    lambda a: a.step(np.array([np.nan, 0.0])),
])
def test_bad_input_raises_and_leaves_object_unchanged(bad_call):
    anc = AdaptiveNotchCanceller(2, [40.0, 80.0], FS, 0.01)
    for _ in range(7):
        anc.step(np.array([0.2, -0.1]))
    before = _snapshot(anc)
    with pytest.raises(ValueError):
        bad_call(anc)
    assert _same(before, _snapshot(anc))


def test_constructor_validation():
    with pytest.raises(ValueError):
        AdaptiveNotchCanceller(6, [40.0, 600.0], FS, 0.01)
    with pytest.raises(ValueError):
        AdaptiveNotchCanceller(6, [40.0], FS, -1.0)
    with pytest.raises(ValueError):
        AdaptiveNotchCanceller(6, [40.0], FS, 0.01, np.eye(6))
    with pytest.raises(ValueError):
        AdaptiveNotchCanceller(0, [40.0], FS, 0.01)


def test_advance_equals_steps_with_zero_error():
    """Skipping missing samples keeps the phase grid, ramp and fading tones exact."""
    def make():
        c = AdaptiveNotchCanceller(6, [40.0, 80.0], FS, 0.01)
        c.set_weights(np.arange(12).reshape(2, 6) * (1 + 0.5j))
        c.set_enabled(False, ramp_samples=30)
        c.set_tone_frequencies([40.0], ramp_samples=40)
        return c

    stepped, skipped = make(), make()
    for _ in range(25):
        stepped.step(np.zeros(6))
    skipped.advance(25)
    np.testing.assert_allclose(skipped.phases_rad, stepped.phases_rad, atol=1e-9)
    assert skipped.output_gain == pytest.approx(stepped.output_gain)
    np.testing.assert_allclose(skipped.step(np.zeros(6)), stepped.step(np.zeros(6)), atol=1e-9)


@pytest.mark.parametrize("centralized,integral,lowpass", [
    (False, False, False), (True, False, False), (False, True, False), (True, True, False),
    (False, True, True), (True, False, True)])
def test_step_does_not_allocate_arrays_across_phasor_resyncs(centralized, integral, lowpass):
    shape = (400, 6, 6) if centralized else (400, 6)
    anc = AdaptiveNotchCanceller(6, np.linspace(1.0, 499.0, 400), FS, 0.01,
                                 np.ones(shape, dtype=complex))
    if integral:
        anc.set_integral_ratio(0.5)
    if lowpass:
        anc.set_update_lowpass(10.0)
    e, out = np.full(6, 0.1), np.zeros(6)
    for _ in range(10):
        anc.step(e, out=out)
    peaks = []
    # tracemalloc counts every thread (pytest-xdist's I/O thread allocates now and then):
    # the least of three measurements; an allocating step would show in every one.
    for _ in range(3):
        tracemalloc.start()
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        for _ in range(600):               # two re-synchronisations of the phasors
            anc.step(e, out=out)
        peaks.append(tracemalloc.get_traced_memory()[1] - base)
        tracemalloc.stop()
    assert min(peaks) < 1024, peaks  # a (400, 6) complex temporary alone: 38400 bytes


def test_output_is_exactly_the_weighted_phasors_over_a_long_run():
    """With mu = 0 the output is Re{W e^{j phi}} of the canceller's own phases, to 1e-12.

    60 000 samples: hundreds of phasor re-synchronisations.
    """
    freqs = [40.0, 80.0, 123.456, 499.9]
    w = np.array([[1.0, 0.3 - 2.0j], [-0.5j, 1.5], [2.0 + 1.0j, -1.0], [0.7, 0.2j]])
    anc = AdaptiveNotchCanceller(2, freqs, FS, 0.0)
    anc.set_weights(w)
    worst = 0.0
    for _ in range(60_000):
        phi = anc.phases_rad
        expected = (w * np.exp(1j * phi)[:, None]).real.sum(axis=0)
        worst = max(worst, np.max(np.abs(anc.step(np.zeros(2)) - expected)))
    assert worst < 1e-12


def test_advance_across_phasor_resyncs_equals_steps_with_zero_error():
    def make():
        c = AdaptiveNotchCanceller(3, [40.0, 97.3, 311.1], FS, 0.01)
        c.set_weights(np.arange(9).reshape(3, 3) * (0.5 - 1j))
        return c

    stepped, skipped = make(), make()
    for _ in range(1000):
        stepped.step(np.zeros(3))
    for _ in range(3):
        skipped.step(np.zeros(3))
    skipped.advance(600)
    for _ in range(397):
        skipped.step(np.zeros(3))
    np.testing.assert_allclose(skipped.phases_rad, stepped.phases_rad, rtol=0, atol=1e-12)
    for _ in range(300):
        np.testing.assert_allclose(skipped.step(np.zeros(3)), stepped.step(np.zeros(3)),
                                   rtol=0, atol=1e-11)


# ----------------------------------------------------------------------------- type-2 update
def _ramp_run(ratio, mu=0.01, seconds=6.0):
    """SISO plant, a 40 Hz disturbance whose amplitude grows steadily (0.1 + 0.05 t)."""
    plant = resonant_plant([60.0])
    g = frequency_response(plant, 40.0)[0]
    anc = AdaptiveNotchCanceller(1, [40.0], FS, mu, -2.0 / g[None])
    anc.set_integral_ratio(ratio)
    n = np.arange(int(seconds * FS))
    amplitude = 0.1 + 0.05 * n / FS
    dist = (amplitude * np.cos(2 * np.pi * 40.0 * n / FS + 0.3))[:, None]
    err = simulate(plant, anc, dist)[:, 0]
    return abs(tone_phasor(err[4000:], 40.0, 4000)), anc


def test_first_order_update_lags_a_steady_change_by_its_time_constant_type_2_does_not():
    """The paper's update leaves the disturbance's change over 1/mu samples; type 2 none.

    0.05 per s x 0.1 s = 5e-3; the rate integrator (damping 0.7) removes it.
    """
    first, _ = _ramp_run(0.0)
    assert first == pytest.approx(0.05 / (0.01 * FS), rel=0.15)
    second, anc = _ramp_run(1.0 / (4 * 0.7 ** 2))
    assert second < 0.01 * first
    # the learnt rate is the converged weight's change per sample: -G^-1 D' (0.05 N/s / fs)
    g = frequency_response(resonant_plant([60.0]), 40.0)[0, 0, 0]
    assert abs(anc.weight_rates[0, 0]) == pytest.approx(0.05 / FS / abs(g), rel=0.05)


def test_type_2_state_is_kept_cleared_and_validated():
    anc = AdaptiveNotchCanceller(2, [40.0, 80.0], FS, 0.05, -2.0 * np.ones((2, 2)))
    plain = AdaptiveNotchCanceller(2, [40.0, 80.0], FS, 0.05, -2.0 * np.ones((2, 2)))
    anc.set_integral_ratio(0.0)
    rng = np.random.default_rng(1)
    errors = rng.standard_normal((50, 2))
    for e in errors:                                   # ratio 0: the paper's update exactly
        np.testing.assert_array_equal(anc.step(e), plain.step(e))
    assert not np.any(anc.weight_rates)
    anc.set_integral_ratio([0.5, 0.0])
    for e in errors:
        anc.step(e)
    rates = anc.weight_rates
    assert np.all(rates[0] != 0) and not np.any(rates[1])
    anc.set_tone_frequencies([40.0, 60.0], coefficients=-2.0 * np.ones((2, 2)))
    np.testing.assert_array_equal(anc.weight_rates[0], rates[0])        # kept tone keeps it
    assert not np.any(anc.weight_rates[1])
    assert anc.integral_ratio.tolist() == [0.5, 0.5]     # a new tone takes the last setting
    anc.set_frozen(True)
    assert not np.any(anc.weight_rates)                   # frozen weights hold
    anc.set_frozen(False)
    for e in errors:
        anc.step(e)
    anc.set_weights(np.full((2, 2), 100.0))
    assert anc.limit_weights(1.0) and not np.any(anc.weight_rates)      # anti-windup
    for bad in (-0.1, [0.5], np.nan):
        with pytest.raises(ValueError, match="integral ratio"):
            anc.set_integral_ratio(bad)
    assert anc.integral_ratio.tolist() == [0.5, 0.5]


# ----------------------------------------------------------------------------- update low-pass
def _measured_canceller_response(anc, freq_hz, channel, seconds=20.0):
    """Column ``channel`` of K at ``freq_hz``: the command's phasor per unit error phasor.

    Open loop, a unit cosine error on one channel; the Hann-windowed lock-in over
    ``seconds`` rejects the undamped tones the start-up leaves in the weights.
    """
    n = np.arange(int(seconds * FS))
    e = np.zeros((n.size, anc.n_channels))
    e[:, channel] = np.cos(2 * np.pi * freq_hz * n / FS)
    u = np.array([anc.step(row) for row in e])
    w = np.hanning(n.size)
    return 2.0 * (w * np.exp(-2j * np.pi * freq_hz * n / FS)) @ u / w.sum()


@pytest.mark.parametrize("corner_hz", [0.0, 10.0])
def test_update_lowpass_shapes_k_as_the_closed_form_says(corner_hz):
    """K measured on the canceller (full P, two tones) equals the closed form.

    With and without the update low-pass; with it the tails 20 Hz from a tone are halved.
    """
    from hexapod_vibration.core.control.sensitivity import canceller_frequency_response

    tones, mu = [40.0, 80.0], 0.002
    rng = np.random.default_rng(3)
    p = rng.standard_normal((2, 3, 3)) + 1j * rng.standard_normal((2, 3, 3))
    for f in (18.7, 60.0, 130.0):
        anc = AdaptiveNotchCanceller(3, tones, FS, mu, p)
        anc.set_update_lowpass(corner_hz)
        measured = _measured_canceller_response(anc, f, channel=1)
        closed = canceller_frequency_response(tones, FS, p, mu, [f],
                                              update_lowpass_hz=corner_hz)[0][:, 1]
        np.testing.assert_allclose(measured, closed, rtol=0.01, atol=1e-3 * np.abs(closed).max())
    far = [18.7]
    with_lp = canceller_frequency_response(tones, FS, p, mu, far, update_lowpass_hz=10.0)
    without = canceller_frequency_response(tones, FS, p, mu, far)
    ratio = np.linalg.norm(with_lp) / np.linalg.norm(without)
    assert 0.35 < ratio < 0.6, ratio                    # ~ 10 Hz / 21.3 Hz from 40 Hz


def test_update_lowpass_keeps_the_notch_and_is_validated():
    """Same converged cancellation at the tone; 0 is the paper's update bit for bit."""
    plant = resonant_plant([60.0, 70.0], coupling=0.2)
    g = frequency_response(plant, 40.0)[0]
    p = -2.0 * np.linalg.inv(g)[None]
    d = np.outer(np.cos(2 * np.pi * 40.0 * np.arange(8000) / FS + 0.3), [1.0, -0.5])
    finals = {}
    for corner in (0.0, 10.0):
        anc = AdaptiveNotchCanceller(2, [40.0], FS, 0.01, p)
        anc.set_update_lowpass(corner)
        assert anc.update_lowpass_hz == corner
        err = simulate(plant, anc, d)
        finals[corner] = sp.to_db_re_g(np.sqrt(np.mean(err[-2000:] ** 2)))
    assert finals[10.0] < -150.0 and finals[0.0] < -150.0, finals
    plain = AdaptiveNotchCanceller(2, [40.0], FS, 0.01, p)
    off = AdaptiveNotchCanceller(2, [40.0], FS, 0.01, p)
    off.set_update_lowpass(0.0)
    for e in np.random.default_rng(0).standard_normal((300, 2)):
        np.testing.assert_array_equal(off.step(e), plain.step(e))
    for bad in (-1.0, np.nan, 500.0):
        with pytest.raises(ValueError, match="update_lowpass_hz"):
            off.set_update_lowpass(bad)
    assert off.update_lowpass_hz == 0.0


def test_adapted_weights_are_the_weights_without_the_filters_lag():
    """With the update low-pass the adapted weights are the paper canceller's weights.

    Open loop (the same errors either way): the filter delays the corrections, loses none.
    """
    p = np.random.default_rng(5).standard_normal((2, 3)) + 0j
    plain = AdaptiveNotchCanceller(3, [40.0, 80.0], FS, 0.01, p)
    filtered = AdaptiveNotchCanceller(3, [40.0, 80.0], FS, 0.01, p)
    filtered.set_update_lowpass(10.0)
    for e in np.random.default_rng(6).standard_normal((500, 3)):
        plain.step(e)
        filtered.step(e)
    np.testing.assert_allclose(filtered.adapted_weights, plain.weights, rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(filtered.weights - plain.weights)) > 1e-3   # the lag is real
    np.testing.assert_array_equal(plain.adapted_weights, plain.weights)
