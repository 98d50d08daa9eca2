"""Tests of hexapod_vibration.core.spectrum on synthetic signals with known content."""

import numpy as np
import pytest

from hexapod_vibration.core import spectrum as sp

FS = 1000.0


def _tones(t, freqs, amps, phases):
    parts = zip(freqs, amps, phases, strict=True)
    return sum(a * np.cos(2 * np.pi * f * t + p) for f, a, p in parts)


def test_db_re_g_and_constants():
    assert sp.G0 == 9.80665
    assert sp.to_db_re_g(sp.G0) == pytest.approx(0.0, abs=1e-12)
    assert sp.to_db_re_g(sp.G0 / 10.0) == pytest.approx(-20.0, abs=1e-12)
    assert sp.main_lobe_half_width_bins("blackmanharris") == 4
    assert sp.main_lobe_half_width_bins("hann") == 2


def test_tone_levels_on_and_off_bin_within_0p2_db():
    rng = np.random.default_rng(11)
    t = np.arange(int(60 * FS)) / FS
    freqs = np.array([40.0, 57.33, 80.05, 123.456, 200.0, 333.37])   # on-bin and off-bin
    amps = np.array([0.5, 0.1, 0.02, 0.3, 0.05, 0.01])
    x = _tones(t, freqs, amps, rng.uniform(0, 2 * np.pi, freqs.size))
    x += 2e-3 * rng.standard_normal(t.size)
    levels = sp.tone_levels_db(x, FS, freqs)
    expected = sp.to_db_re_g(amps / np.sqrt(2))
    assert np.max(np.abs(levels - expected)) < 0.2
    assert np.allclose(sp.tone_rms(x, FS, freqs), amps / np.sqrt(2), rtol=0.023)


def test_psd_integrates_to_variance():
    rng = np.random.default_rng(2)
    x = 0.05 * rng.standard_normal(int(40 * FS))
    f, psd = sp.power_spectral_density(x, FS)
    assert f[1] - f[0] == pytest.approx(1.0 / sp.DEFAULT_SEGMENT_S)
    assert np.sum(psd) * (f[1] - f[0]) == pytest.approx(np.var(x), rel=0.02)


@pytest.mark.parametrize("f_strong", [40.0, 40.05, 40.03, 39.95])
def test_tones_1hz_apart_70db_apart_are_separated(f_strong):
    rng = np.random.default_rng(5)
    t = np.arange(int(60 * FS)) / FS
    a_strong, a_weak = 1.0, 10 ** (-70 / 20)
    freqs = [f_strong, f_strong + 1.0]
    x = _tones(t, freqs, [a_strong, a_weak], [0.3, 1.1]) + 1e-6 * rng.standard_normal(t.size)
    levels = sp.tone_levels_db(x, FS, freqs)
    expected = sp.to_db_re_g(np.array([a_strong, a_weak]) / np.sqrt(2))
    assert abs(levels[0] - expected[0]) < 0.2
    assert abs(levels[1] - expected[1]) < 1.0
    # The weak tone alone measures the same: the strong one leaks < -90 dB into it.
    assert abs(levels[1] - expected[1]) < 0.1


def test_noise_floor_matches_white_noise_in_tone_bandwidth():
    rng = np.random.default_rng(8)
    sigma = 0.01
    x = sigma * rng.standard_normal(int(120 * FS)) + 0.2 * np.cos(2 * np.pi * 100.0
                                                                  * np.arange(120000) / FS)
    bins = 2 * sp.main_lobe_half_width_bins("blackmanharris") + 1
    expected_rms = np.sqrt(sigma ** 2 / (FS / 2) * bins / sp.DEFAULT_SEGMENT_S)
    floor = sp.noise_floor_db(x, FS, 100.0)
    # 2 Hz band: ~12 floor bins, std 0.3 dB (30 seeds: bias -0.07 dB); 10 Hz band: 0.17 dB
    assert floor == pytest.approx(sp.to_db_re_g(expected_rms), abs=1.0)
    wide = sp.noise_floor_db(x, FS, 100.0, band_hz=10.0)
    assert wide == pytest.approx(sp.to_db_re_g(expected_rms), abs=0.5)
    # excluding another tone's main lobe does not change a white floor
    assert sp.noise_floor_db(x, FS, 100.0, exclude_hz=[101.0]) == pytest.approx(floor, abs=1.0)
    # a tone at the noise floor is not reported as a strong tone
    assert sp.tone_levels_db(x, FS, [150.0])[0] < floor + 3.0


def _clipped_sine_harmonics(clip, n_harm):
    """Reference: Fourier sine coefficients of clip(sin(theta)) from one dense period."""
    theta = 2 * np.pi * np.arange(2 ** 16) / 2 ** 16
    spec = np.fft.rfft(np.clip(np.sin(theta), -clip, clip)) * 2 / theta.size
    return np.abs(spec[1:n_harm + 1])


def test_harmonic_distortion_of_clipped_sine():
    fs, f0, clip, amp = 4000.0, 50.3, 0.5, 1.0
    t = np.arange(int(30 * fs)) / fs
    rng = np.random.default_rng(3)
    x = amp * np.clip(np.sin(2 * np.pi * f0 * t), -clip, clip) + 1e-5 * rng.standard_normal(
        t.size)
    hd = sp.harmonic_distortion(x, fs, f0, n_harmonics=5)
    ref = amp * _clipped_sine_harmonics(clip, 5)
    ref_thd = np.sqrt(np.sum(ref[1:] ** 2)) / ref[0]
    assert hd["frequencies_hz"] == pytest.approx([f0 * k for k in range(1, 6)])
    odd = [0, 2, 4]
    assert np.allclose(np.array(hd["levels_db"])[odd], sp.to_db_re_g(ref[odd] / np.sqrt(2)),
                       atol=0.2)
    assert np.all(np.array(hd["levels_db"])[[1, 3]] < hd["levels_db"][0] - 100)
    assert hd["thd_ratio"] == pytest.approx(ref_thd, rel=0.01)
    assert hd["thd_percent"] == pytest.approx(100 * ref_thd, rel=0.01)
    assert 0.15 < hd["thd_ratio"] < 0.30   # a sine clipped at half amplitude: ~21 %


def test_harmonics_above_nyquist_are_dropped():
    x = np.cos(2 * np.pi * 150.0 * np.arange(20000) / FS)
    hd = sp.harmonic_distortion(x, FS, 150.0, n_harmonics=5)
    assert hd["frequencies_hz"] == [150.0, 300.0, 450.0]


def test_tone_level_over_time_follows_amplitude_step():
    t = np.arange(int(10 * FS)) / FS
    amp = np.where(t < 5.0, 0.4, 0.04)
    x = amp * np.cos(2 * np.pi * 40.0 * t + 0.5) + 0.1 * np.cos(2 * np.pi * 55.0 * t)
    window = sp.level_window_s(40.0, [55.0])
    assert window == pytest.approx(4.5 / 15.0)
    t_lev, rms = sp.tone_level_over_time(x + sp.G0, FS, 40.0, window)
    # only complete windows: the first centre is half a window in, none past the end
    assert t_lev[0] == pytest.approx(0.5 * (window - 1 / FS), abs=1e-9)
    assert t_lev[-1] <= t[-1] - 0.5 * window + 0.01
    far = np.abs(t_lev - 5.0) > 0.5 * window + 0.01
    assert np.allclose(rms[far & (t_lev < 5.0)], 0.4 / np.sqrt(2), rtol=1e-3)
    assert np.allclose(rms[far & (t_lev > 5.0)], 0.04 / np.sqrt(2), rtol=1e-2)


def test_tone_level_over_time_rejects_gravity_and_a_neighbour_1hz_away():
    """Close tones: 39 Hz 73 dB below 40 Hz, with 1 g of gravity, measured within 1.1 dB.

    A neighbour rejected by 92 dB leaves 19 dB below the weak tone: +-1.0 dB of ripple.
    """
    t = np.arange(int(20 * FS)) / FS
    weak, strong = sp.G0 * 10 ** (-110 / 20), sp.G0 * 10 ** (-37 / 20)   # RMS (m/s^2)
    x = (sp.G0 + np.sqrt(2) * weak * np.cos(2 * np.pi * 39.0 * t)
         + np.sqrt(2) * strong * np.cos(2 * np.pi * 40.0 * t + 0.7))
    window = sp.level_window_s(39.0, [37.0, 38.0, 40.0, 41.0, 42.0])
    assert window == pytest.approx(4.5)
    _, rms = sp.tone_level_over_time(x, FS, 39.0, window)
    assert np.all(np.abs(sp.to_db_re_g(rms) - (-110.0)) < 1.1)


def test_tone_level_over_time_never_spans_a_missing_sample():
    t = np.arange(4000) / FS
    x = np.cos(2 * np.pi * 40.0 * t)
    index = np.delete(np.arange(4000), np.arange(2000, 2010))
    t_lev, rms = sp.tone_level_over_time(x[index], FS, 40.0, 0.2, index=index)
    half = 0.5 * (0.2 * FS - 1)          # samples either side of a window's centre
    first, last = t_lev * FS - half, t_lev * FS + half
    assert not np.any((first <= 2009) & (last >= 2000))
    assert np.any(last == 1999) and np.any(first == 2010)   # but right up to the gap
    assert np.allclose(rms, 1 / np.sqrt(2), rtol=1e-3)


def test_convergence_time_on_exponential_within_one_step():
    dt, t_on, tau = 0.01, 5.0, 0.5
    t = np.arange(0.0, 30.0, dt)
    level = np.where(t < t_on, -20.0, -60.0 + 40.0 * np.exp(-(t - t_on) / tau))
    expected = tau * np.log(40.0 / 3.0)   # 40 dB above final decays to 3 dB: 1.295 s
    got = sp.convergence_time_s(t, level, t_on)
    assert abs(got - expected) <= dt


def test_convergence_time_is_first_passage_and_nan_without_data_after_control_on():
    """The level fluctuating around a floor after it got there still converged then."""
    t = np.arange(0.0, 20.0, 0.01)
    rng = np.random.default_rng(4)
    floor = 10 * np.log10(rng.exponential(size=t.size))       # Rayleigh level, 5.6 dB std
    level = np.where(t < 8.0, 0.0, -60.0) + np.where(t < 8.0, 0.0, floor)
    got = sp.convergence_time_s(t, level, 5.0)
    assert 3.0 <= got <= 3.2
    assert np.isnan(sp.convergence_time_s(t, np.zeros_like(t), 25.0))


def test_tone_convergence_is_the_one_definition():
    """tone_convergence = level over time + convergence_time_s, on a decaying tone."""
    t = np.arange(int(20 * FS)) / FS
    on, tau = 5000, 0.5
    amp = np.where(t < 5.0, 1.0, np.exp(-(t - 5.0) / tau) + 1e-4)
    x = sp.G0 + amp * np.cos(2 * np.pi * 40.0 * t) + 0.3 * np.cos(2 * np.pi * 80.0 * t)
    result = sp.tone_convergence(x, FS, 40.0, on, other_hz=[80.0])
    t_lev, rms = sp.tone_level_over_time(x, FS, 40.0, result["window_s"])
    assert result["window_s"] == pytest.approx(0.2)
    np.testing.assert_allclose(result["t_s"], t_lev)
    expected = sp.convergence_time_s(t_lev, sp.to_db_re_g(rms), on / FS)
    assert result["convergence_s"] == expected
    # amplitude exp(-t/tau) + 1e-4 is within 3 dB (x sqrt 2) of 1e-4 after
    # tau ln(1 / (0.414e-4)) = 5.04 s; the 0.2 s window shifts that by less than 0.1 s
    assert result["convergence_s"] == pytest.approx(0.5 * np.log(1 / (np.sqrt(2) - 1) / 1e-4),
                                                    abs=0.1)
    assert result["final_level_db"] == pytest.approx(sp.to_db_re_g(1e-4 / np.sqrt(2)),
                                                     abs=0.3)


def test_floor_and_level_do_not_depend_on_the_other_tones_requested():
    rng = np.random.default_rng(9)
    t = np.arange(int(30 * FS)) / FS
    x = (1e-3 * rng.standard_normal(t.size) + 0.1 * np.cos(2 * np.pi * 39.0 * t)
         + 0.1 * np.cos(2 * np.pi * 40.0 * t) + sp.G0)
    alone = sp.tone_and_floor_db(x, FS, [38.0])
    many = sp.tone_and_floor_db(x, FS, [37.0, 38.0, 39.0, 40.0, 41.0, 42.0])
    assert alone[0][0] == many[0][1] and alone[1][0] == many[1][1]
    assert sp.noise_floor_db(x, FS, 38.0) == pytest.approx(alone[1][0])


def test_harmonic_distortion_counts_every_harmonic_below_nyquist():
    t = np.arange(int(12 * FS)) / FS
    amps = {40.0: 1.0, 80.0: 0.1, 280.0: 0.2, 480.0: 0.05}
    x = sum(a * np.cos(2 * np.pi * f * t) for f, a in amps.items())
    hd = sp.harmonic_distortion(x, FS, 40.0)
    assert hd["harmonics"] == 11
    assert hd["frequencies_hz"] == [40.0 * k for k in range(1, 13)]
    expected = np.sqrt(0.1 ** 2 + 0.2 ** 2 + 0.05 ** 2)
    assert hd["thd_ratio"] == pytest.approx(expected, rel=0.01)
    assert hd["relative_db"][6] == pytest.approx(20 * np.log10(0.2), abs=0.1)


def test_short_signal_warns_and_uses_one_segment():
    x = np.cos(2 * np.pi * 40.0 * np.arange(3000) / FS)
    with pytest.warns(sp.ShortSignalWarning):
        f, _ = sp.power_spectral_density(x, FS)
    assert f[1] - f[0] == pytest.approx(FS / 3000)
    with pytest.warns(sp.ShortSignalWarning):
        level = sp.tone_levels_db(x, FS, [40.0])[0]
    assert level == pytest.approx(sp.to_db_re_g(1 / np.sqrt(2)), abs=0.2)


def test_bad_tone_frequency_raises():
    x = np.zeros(20000)
    with pytest.raises(ValueError):
        sp.tone_rms(x, FS, [600.0])
    with pytest.raises(ValueError):
        sp.tone_rms(x, FS, [0.0])


def test_band_levels_of_white_noise_and_a_tone_left_out():
    """A band's level is its share of white noise; an excluded tone does not count."""
    fs, n = 1000.0, 300_000            # 300 s: each band within ~0.2 dB (1 sigma)
    rng = np.random.default_rng(7)
    sigma = 0.01
    noise = sigma * rng.normal(size=n)
    tone = 0.5 * np.sin(2 * np.pi * 40.0 * np.arange(n) / fs)
    bands = sp.third_octave_bands_hz(10.0, 200.0)
    assert np.allclose(bands[:4, 0], [10.0, 12.589, 15.849, 19.953], atol=1e-3)
    expected = sp.to_db_re_g(sigma * np.sqrt((bands[:, 2] - bands[:, 1]) / (fs / 2)))
    without = sp.band_levels_db(noise, fs, bands)
    with_tone = sp.band_levels_db(noise + tone, fs, bands, exclude_hz=[40.0])
    assert np.max(np.abs(without - expected)) < 0.8
    assert np.max(np.abs(with_tone - without)) < 0.3      # the 40 Hz line is left out
    assert sp.band_levels_db(noise + tone, fs, bands)[6] > without[6] + 20.0
