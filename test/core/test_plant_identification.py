"""Broadband identification of G(f): the excitation, a coupled test plant, the PPH loop."""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.core.control.plant_identification import (
    BroadbandIdentifier,
    response_from_periods,
    zippered_odd_multisine,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from linear_plants import (  # noqa: E402
    FS,
    frequency_response,
    resonance_bank,
    simulate,
    simulate_with_gaps,
)


def _coupled_plant(seed=1):
    a, b, c = resonance_bank([30.0, 55.0, 90.0], 0.1, 1.0)
    mix = np.eye(3) + 0.3 * np.random.default_rng(seed).normal(size=(3, 3))
    return a, b @ mix, c


def test_design_excites_odd_bins_once_each_with_the_asked_rms():
    design = zippered_odd_multisine(6, FS, period_s=8.0, amplitude_rms_n=2.0)
    assert np.all(design.bins % 2 == 1)
    assert np.unique(design.bins).size == design.bins.size
    table = design.period_table()
    assert table.shape == (8000, 6)
    assert np.allclose(np.sqrt(np.mean(table ** 2, axis=0)), 2.0, rtol=1e-9)
    spectrum = np.abs(np.fft.rfft(table, axis=0))
    assert np.max(spectrum[0::2]) < 1e-9 * np.max(spectrum)     # nothing on even bins
    for j in range(6):                                           # channel j: its lines only
        own = design.bins[design.channel_of_bin == j]
        others = np.setdiff1d(design.bins, own)
        assert np.max(spectrum[others, j]) < 1e-9 * np.max(spectrum[own, j])


def test_bad_designs_are_refused():
    with pytest.raises(ValueError, match="n_channels"):
        zippered_odd_multisine(0, FS)
    with pytest.raises(ValueError, match="period_s"):
        zippered_odd_multisine(6, FS, period_s=0.0105)
    with pytest.raises(ValueError, match="amplitude_rms_n"):
        zippered_odd_multisine(6, FS, amplitude_rms_n=-1.0)
    with pytest.raises(ValueError, match="fewer than 2 lines"):
        zippered_odd_multisine(6, FS, period_s=1.0, min_frequency_hz=490.0)


@pytest.fixture(scope="module")
def coupled_run():
    """The coupled plant under noise, a tone on the even grid and one off it."""
    plant = _coupled_plant()
    ident = BroadbandIdentifier(3, FS, period_s=4.0, settle_s=1.0, periods=2)
    n = int(round(ident.duration_s * FS))
    t = np.arange(n) / FS
    rng = np.random.default_rng(2)
    dist = (1e-3 * rng.normal(size=(n, 3)) + 0.5 * np.sin(2 * np.pi * 40.0 * t)[:, None]
            + 0.2 * np.sin(2 * np.pi * 63.3 * t)[:, None])
    simulate(plant, ident, dist)
    return plant, ident


def test_response_matches_the_exact_one_despite_the_tones(coupled_run):
    plant, ident = coupled_run
    f = np.arange(20.0, 300.0, 0.37)
    f = f[np.abs(f - 63.3) > 4.0]          # the gap left by the dropped lines (below)
    exact = frequency_response(plant, f)
    error = (np.linalg.norm(ident.result().at(f) - exact, axis=(1, 2))
             / np.linalg.norm(exact, axis=(1, 2)))
    assert np.median(error) < 0.005
    assert np.max(error) < 0.02


def test_lines_next_to_an_off_grid_tone_are_dropped(coupled_run):
    _, ident = coupled_run
    response = ident.result()
    kept = np.concatenate(response.line_frequencies_hz)
    excited = ident.design.frequencies_hz
    assert np.min(np.abs(kept - 63.3)) > 0.3                    # leakage lines dropped
    band = (excited > 20.0) & (excited < 300.0)                 # where the SNR is good,
    kept_band = (kept > 20.0) & (kept < 300.0)                  # few others are dropped
    assert np.count_nonzero(kept_band) >= np.count_nonzero(band) - 3
    assert np.any(np.abs(excited - 40.0) < 0.3)                 # the on-grid tone: no harm
    assert np.count_nonzero(np.abs(kept - 40.0) < 0.3) == 2    # both lines beside it kept


def test_disturbance_spectrum_measures_the_noise_and_leaves_the_lines_out():
    """White noise and a line on the even grid (a tone off it leaks everywhere: no window)."""
    plant = _coupled_plant()
    ident = BroadbandIdentifier(3, FS, period_s=4.0, settle_s=1.0, periods=2)
    n = int(round(ident.duration_s * FS))
    t = np.arange(n) / FS
    rng = np.random.default_rng(3)
    dist = 1e-3 * rng.normal(size=(n, 3)) + 0.5 * np.sin(2 * np.pi * 40.0 * t)[:, None]
    simulate(plant, ident, dist)
    spectrum = ident.disturbance(smoothing_hz=8.0)
    csd = spectrum.at([100.0, 200.0, 300.0])
    expected = 2.0 * 1e-6 / FS                                  # white, sigma 1e-3, one-sided
    diag = np.real(np.diagonal(csd, axis1=1, axis2=2))
    assert np.allclose(diag, expected, rtol=0.35)
    assert np.max(np.abs(csd - diag[:, :, None] * np.eye(3))) < 0.6 * expected
    assert np.real(spectrum.at([40.0])[0, 0, 0]) < 2.0 * expected   # the 40 Hz line left out


def test_result_before_the_end_is_refused():
    ident = BroadbandIdentifier(2, FS, period_s=1.0, settle_s=0.0)
    ident.step(np.zeros(2))
    with pytest.raises(RuntimeError, match="not finished"):
        ident.result()
    with pytest.raises(ValueError, match="shape"):
        ident.step(np.zeros(3))


def test_pph_loop_response_matches_its_impulse_response():
    """The running PPH (linear, shaker on) against the quiet plant's impulse response."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from sensitivity_loop import IdentifyingLoop, ImpulseIdentifier, ImpulseLoop

    from hexapod_vibration.core.model.config import load_model_config
    from hexapod_vibration.core.sim.scenario import ShakerSettings, load_scenario

    root = Path(__file__).resolve().parents[2]
    scenario = load_scenario(root / "config" / "scenarios" / "close_tones.yaml")
    scenario = dataclasses.replace(scenario, nonlinear=False, identify_at_s=6.0,
                                   window_s=0.5)
    quiet = load_model_config(root / "config" / "pph_model.yaml", {
        "accelerometer": {"noise_density_g_per_sqrt_hz": 0.0, "bits": 24},
        "eddy": {"noise_rms_m": 0.0}})
    impulse = ImpulseIdentifier(record_s=10.0)
    end = 6.0 + impulse.duration_s + 0.5
    ImpulseLoop(quiet, dataclasses.replace(scenario, shaker=ShakerSettings(),
                                           duration_s=end, control_on_s=end), impulse).run()
    f_ref, g_ref = impulse.result()
    running = IdentifyingLoop(load_model_config(root / "config" / "pph_model.yaml"),
                              dataclasses.replace(scenario, duration_s=17.0,
                                                  control_on_s=17.0),
                              enable_control=False)
    running.run()
    for lo, hi, median, worst in ((35.0, 45.0, 0.005, 0.01), (45.0, 450.0, 0.003, 0.01)):
        sel = (f_ref >= lo) & (f_ref < hi)
        error = (np.linalg.norm(running.response.at(f_ref[sel]) - g_ref[sel], axis=(1, 2))
                 / np.linalg.norm(g_ref[sel], axis=(1, 2)))
        assert np.median(error) < median, (lo, hi)
        assert np.max(error) < worst, (lo, hi)


# ------------------------------------------------------------- a disturbance next to a tone
def _identify(identifier, disturbance_hz, amplitude, seed=4):
    """Run ``identifier`` on six resonances with a disturbance line at ``disturbance_hz``."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from linear_plants import resonance_bank, simulate

    plant = resonance_bank([25.0, 30.0, 34.0, 46.0, 52.0, 60.0], 0.05, 0.1)
    samples = int(round(identifier.duration_s * FS))
    n = np.arange(samples)
    rng = np.random.default_rng(seed)
    mix = np.linspace(0.6, 1.4, 6)
    dist = (amplitude * mix * np.cos(2 * np.pi * disturbance_hz * n / FS + 0.4)[:, None]
            + 1e-3 * rng.standard_normal((samples, 6)))
    simulate(plant, identifier, dist)
    return identifier


def test_identification_survives_a_disturbance_04hz_from_the_tone():
    """Gain within 10 %, phase within 10 degrees of the disturbance-free result."""
    quiet = _identify(BroadbandIdentifier(6, FS), 40.4, 0.0).result()
    disturbed_run = _identify(BroadbandIdentifier(6, FS), 40.4, 0.5)
    disturbed = disturbed_run.result()
    assert [round(line.frequency_hz, 3) for line in disturbed_run.removed_lines()] == [40.4]
    g0 = np.diagonal(quiet.at([40.0])[0])
    g1 = np.diagonal(disturbed.at([40.0])[0])
    assert np.all(np.abs(np.abs(g1 / g0) - 1.0) < 0.10)
    assert np.all(np.abs(np.rad2deg(np.angle(g1 / g0))) < 10.0)
    assert disturbed.uncertainty_at([40.0])[0] < 0.1           # the supervisor accepts it
    # Without the line removal the same record is useless (the leakage of 40.4 Hz).
    raw = response_from_periods(disturbed_run.design, disturbed_run._aligned_periods())
    assert raw.uncertainty_at([40.0])[0] > 0.1


def test_the_tone_identification_sees_that_the_disturbance_moved():
    """The test-tone method is corrupted by the same disturbance, and says so."""
    from hexapod_vibration.core.control.adaptation import ToneResponseIdentifier

    quiet = _identify(ToneResponseIdentifier(6, [40.0], FS), 40.4, 0.0)
    disturbed = _identify(ToneResponseIdentifier(6, [40.0], FS), 40.4, 0.5)
    assert quiet.baseline_change()[0] < 0.05
    assert disturbed.baseline_change()[0] > 0.25                # refused by the supervisor
    error = np.abs(np.diagonal(disturbed.result()[0]) / np.diagonal(quiet.result()[0]) - 1)
    assert np.max(error) > 0.1


def test_disturbance_lines_hold_the_lines_on_and_off_the_grid(coupled_run):
    _, ident = coupled_run
    lines = sorted(ident.disturbance_lines(), key=lambda line: line.frequency_hz)
    assert [round(line.frequency_hz, 2) for line in lines] == [40.0, 63.3]
    assert np.allclose([np.max(line.amplitude) for line in lines], [0.5, 0.2], rtol=0.3)


def test_missing_samples_are_left_out_of_the_broadband_record():
    """Errors that never arrived are interpolated, not restarted over.

    The input is the designed one here: the commands went out, their sensor samples were lost.
    """
    plant = _coupled_plant()
    exact = frequency_response(plant, np.arange(20.0, 300.0, 0.37))
    for fraction, worst in ((0.01, 0.05), (0.06, None)):
        ident = BroadbandIdentifier(3, FS, period_s=4.0, settle_s=1.0, periods=2)
        n = int(round(ident.duration_s * FS))
        t = np.arange(n) / FS
        dist = (1e-3 * np.random.default_rng(2).normal(size=(n, 3))
                + 0.5 * np.sin(2 * np.pi * 40.0 * t)[:, None])
        lost = np.random.default_rng(7).random(n) < fraction
        table = ident.design.period_table()
        simulate_with_gaps(plant, ident, dist, lost,
                           sent=lambda k, table=table: table[k % table.shape[0]])
        measured = lost[int(FS * 1.0):]
        assert ident.done and ident.missing == np.count_nonzero(measured)
        if worst is None:
            assert ident.missing_refusal() == (
                f"{ident.missing} of its 8000 measured samples "
                f"({100 * ident.missing / 8000:.1f} %) missing (> 5 %)")
            continue
        assert ident.missing_refusal() == ""
        got = ident.result().at(np.arange(20.0, 300.0, 0.37))
        error = np.linalg.norm(got - exact, axis=(1, 2)) / np.linalg.norm(exact, axis=(1, 2))
        assert np.median(error) < 0.01 and np.max(error) < worst


def test_a_late_command_corrupts_the_broadband_input_and_the_uncertainty_says_so():
    """Commands held instead of the designed ones: the uncertainty says how far G is off.

    1 % held: far above the 10 % the supervisor accepts at the tones; 0.1 % held: within it.
    """
    plant = _coupled_plant()
    for fraction, accepted in ((0.001, True), (0.01, False)):
        ident = BroadbandIdentifier(3, FS, period_s=4.0, settle_s=1.0, periods=2)
        n = int(round(ident.duration_s * FS))
        dist = 1e-3 * np.random.default_rng(2).normal(size=(n, 3))
        held = np.random.default_rng(7).random(n) < fraction
        a, b, c = plant
        x, u = np.zeros(a.shape[0]), np.zeros(3)
        for k in range(n):
            command = ident.step(c @ x + dist[k])
            u = u if held[k] else command
            x = a @ x + b @ u
        uncertainty = float(np.max(ident.result().uncertainty_at([40.0, 80.0])))
        assert (uncertainty < 0.1) == accepted, (fraction, uncertainty)
