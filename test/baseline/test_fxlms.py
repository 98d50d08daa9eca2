"""Tests of the filtered-x LMS baseline and of the benchmark's measuring functions.

A synthetic 6x6 FIR plant with the loop timing of docs/architecture.md (a command of sample
n is first seen in the error of sample n+1) stands in for the hexapod, so the tests are
fast and exact. No timing value or cost ratio is asserted: timings belong in the
benchmark's output, never in pass/fail tests.
"""

import dataclasses
import json
import math

import numpy as np
import pytest

from hexapod_vibration.baseline.fxlms import (
    FilteredXLMSController,
    FxlmsCoreLoop,
    SecondaryPathIdentifier,
    fir_frequency_response,
    multiply_adds_per_sample,
)
from hexapod_vibration.bench import cli, costs, table1
from hexapod_vibration.core.control.adaptation import ToneResponseIdentifier
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.paths import config_path

FS = 1000.0
C = 6
TRUE_TAPS = 24


def fir_paths(seed=0):
    """(6, 6, 24) impulse responses: damped resonant diagonal, weaker random coupling."""
    rng = np.random.default_rng(seed)
    lag = np.arange(TRUE_TAPS)
    h = 0.03 * rng.standard_normal((C, C, TRUE_TAPS)) * np.exp(-lag / 6.0)
    diag = 0.1 * np.exp(-(lag - 1) / 4.0) * np.cos(2 * np.pi * 0.05 * lag)
    h += np.eye(C)[:, :, None] * diag
    h[:, :, 0] = 0.0                                   # no feed-through: one-sample delay
    return h


class FIRPlant:
    """e_n = sum_{l >= 1} h[:, :, l] u_{n-l} + d_n: the command of sample n acts from n+1."""

    def __init__(self, h):
        self.h = h[:, :, 1:]
        self.past = np.zeros((h.shape[2] - 1, h.shape[1]))   # u_{n-1}, u_{n-2}, ...

    def output(self):
        return np.einsum("ijl,lj->i", self.h, self.past)

    def push(self, u):
        self.past[1:] = self.past[:-1]
        self.past[0] = u


def run_loop(plant, controller, dist):
    errors = np.empty_like(dist)
    for n in range(dist.shape[0]):
        e = plant.output() + dist[n]
        errors[n] = e
        plant.push(controller.step(e))
    return errors


def disturbance(n_samples, freqs_hz, amp=0.5, noise=1e-4, seed=3):
    rng = np.random.default_rng(seed)
    n = np.arange(n_samples)[:, None]
    d = noise * rng.standard_normal((n_samples, C))
    phasors = []
    for f in freqs_hz:
        ph = amp * np.exp(1j * rng.uniform(0, 2 * np.pi, C))
        phasors.append(ph)
        d += (ph[None, :] * np.exp(2j * np.pi * f * n / FS)).real
    return d, np.array(phasors)


def tone_rms(x, f, n0=0):
    """RMS per channel of the tone f in x (least squares on cos/sin/const)."""
    n = n0 + np.arange(x.shape[0])
    reg = np.column_stack([np.cos(2 * np.pi * f * n / FS), np.sin(2 * np.pi * f * n / FS),
                           np.ones(n.size)])
    coef, *_ = np.linalg.lstsq(reg, x, rcond=None)
    return np.sqrt(0.5 * (coef[0] ** 2 + coef[1] ** 2))


# ----------------------------------------------------------------------------- identification
def test_identification_recovers_fir_plant_despite_disturbance_tone():
    h = fir_paths()
    plant = FIRPlant(h)
    ident = SecondaryPathIdentifier(C, FS, n_taps=32, amplitude_n=1.0, settle_s=0.05,
                                    measure_s=0.5, nuisance_frequencies_hz=[40.0], seed=1)
    dist, _ = disturbance(int(round(ident.duration_s * FS)), [40.0], noise=1e-3)
    run_loop(plant, ident, dist)
    assert ident.done and ident.progress == 1.0
    s = ident.result()
    expected = np.zeros((C, C, 32))
    expected[:, :, :TRUE_TAPS] = h
    assert s.shape == (C, C, 32)
    assert np.max(np.abs(s - expected)) < 0.01 * np.max(np.abs(h))


def test_identification_rejects_bad_arguments():
    with pytest.raises(ValueError, match="n_taps"):
        SecondaryPathIdentifier(C, FS, n_taps=16)
    with pytest.raises(ValueError, match="measure_s"):
        SecondaryPathIdentifier(C, FS, n_taps=64, measure_s=0.1)
    ident = SecondaryPathIdentifier(C, FS, n_taps=32)
    with pytest.raises(RuntimeError, match="not finished"):
        ident.result()
    with pytest.raises(ValueError, match="shape"):
        ident.step(np.zeros(3))


def test_fir_response_matches_tone_identifier_convention():
    """fir_frequency_response uses the same phasor pairing as ToneResponseIdentifier."""
    h = fir_paths(seed=2)
    tones = [40.0, 80.0]
    ident = ToneResponseIdentifier(C, tones, FS)
    run_loop(FIRPlant(h), ident, np.zeros((int(round(ident.duration_s * FS)), C)))
    g_tone = ident.result()
    g_fir = fir_frequency_response(h, tones, FS)
    assert np.max(np.abs(g_fir - g_tone)) < 1e-3 * np.max(np.abs(g_tone))


# ----------------------------------------------------------------------------- control
def test_fxlms_with_identified_paths_reduces_two_tones_by_30_db():
    h = fir_paths()
    plant = FIRPlant(h)
    tones = [40.0, 80.0]
    ident = SecondaryPathIdentifier(C, FS, n_taps=32, settle_s=0.05, measure_s=0.4,
                                    nuisance_frequencies_hz=tones)
    n_id = int(round(ident.duration_s * FS))
    n_total = n_id + 20000
    dist, _ = disturbance(n_total, tones)
    run_loop(plant, ident, dist[:n_id])
    ctl = FilteredXLMSController(ident.result(), tones, FS, mu=0.05)
    errors = run_loop(plant, ctl, dist[n_id:])
    for f in tones:
        before = tone_rms(dist[n_id:n_id + 2000], f, n_id)
        after = tone_rms(errors[-2000:], f, n_total - 2000)
        reduction = 20 * np.log10(before / after)
        assert np.all(reduction > 30.0), (f, reduction)


def test_converged_weights_cancel_the_disturbance_phasor():
    """At convergence G(w) U = -D, with U the filters' command phasor (notch convention)."""
    h = fir_paths(seed=4)
    f = 40.0
    dist, phasors = disturbance(15000, [f], noise=0.0)
    paths = np.pad(h, ((0, 0), (0, 0), (0, 32 - TRUE_TAPS)))     # exact model, L = 32
    ctl = FilteredXLMSController(paths, [f], FS, mu=0.1)
    run_loop(FIRPlant(h), ctl, dist)
    u = ctl.equivalent_tone_weights()[0]
    g = fir_frequency_response(h, [f], FS)[0]
    residual = g @ u + phasors[0]
    assert np.max(np.abs(residual)) < 1e-3 * np.max(np.abs(phasors[0]))


def test_step_interface_warmup_disable_and_validation():
    h = np.pad(fir_paths(), ((0, 0), (0, 0), (0, 40)))     # L = 64
    ctl = FilteredXLMSController(h, [40.0, 80.0], FS, n_taps=32)
    e = np.full(C, 0.1)
    out = np.zeros(C)
    for _ in range(64 + 32 - 1):                           # warm-up: no adaptation yet
        assert ctl.step(e, out) is out
    assert not np.any(ctl.weights)
    u = ctl.step(e)
    assert u.shape == (C,) and np.any(ctl.weights) and np.all(np.isfinite(u))
    ctl.set_enabled(False)
    w = ctl.weights
    assert not np.any(ctl.step(e)) and np.array_equal(ctl.weights, w)
    ctl.set_enabled(True)
    ctl.set_frozen(True)
    ctl.step(e)
    assert np.array_equal(ctl.weights, w)
    ctl.reset_weights()
    assert not np.any(ctl.weights)
    with pytest.raises(ValueError):
        ctl.step(np.zeros(5))
    with pytest.raises(ValueError):
        ctl.set_mu(-1.0)
    with pytest.raises(ValueError, match="length L"):
        FilteredXLMSController(np.zeros((C, C, 16)), [40.0], FS)
    with pytest.raises(ValueError):
        FilteredXLMSController(h, [600.0], FS)
    with pytest.raises(ValueError):
        FilteredXLMSController(h, [], FS)
    # K=2 tones: references 4K, filtered references K*I*J*L, error scaling I, gradient
    # K*I*J*N, update and output K*J*N each (a third K*J*N with leakage)
    assert multiply_adds_per_sample(6, 6, 64, 32, 2) == (
        4 * 2 + 2 * 36 * 64 + 6 + 2 * 36 * 32 + 2 * 2 * 6 * 32)
    assert (multiply_adds_per_sample(6, 6, 64, 32, 2, leakage=True)
            - multiply_adds_per_sample(6, 6, 64, 32, 2)) == 2 * 6 * 32


def test_per_tone_references_ignore_an_uncontrolled_tone():
    """An uncontrolled tone does not leak into the per-tone filters.

    With one reference per tone a strong uncontrolled 120 Hz tone in the error leaves the
    40 and 80 Hz cancellation intact (a single summed reference left ~20-30 dB here).
    """
    h = fir_paths()
    paths = np.pad(h, ((0, 0), (0, 0), (0, 32 - TRUE_TAPS)))
    tones = [40.0, 80.0]
    n = 20000
    dist, _ = disturbance(n, tones + [120.0])
    errors = run_loop(FIRPlant(h), FilteredXLMSController(paths, tones, FS, mu=0.05), dist)
    for f in tones + [120.0]:
        reduction = 20 * np.log10(tone_rms(dist[:2000], f) / tone_rms(errors[-2000:], f, n - 2000))
        if f in tones:
            assert np.all(reduction > 60.0), (f, reduction)
        else:
            assert np.all(np.abs(reduction) < 1.0), (f, reduction)


def _reference_fxlms(paths, freqs, mu, n_taps, errors):
    """Explicit loops over the textbook multiple-reference FxLMS (class docstring)."""
    n_i, n_j, n_l = paths.shape
    w = 2 * np.pi * np.asarray(freqs) / FS
    amps = []
    for wk in w:
        g = sum(paths[:, :, tap] * np.exp(-1j * wk * tap) for tap in range(n_l))
        amps.append(1.0 / math.sqrt(1e-12 + 0.5 * n_taps * np.sum(np.abs(g) ** 2)))

    def x(k, n):
        return amps[k] * math.cos(w[k] * n) if n >= 0 else 0.0

    r = np.zeros((len(errors), len(freqs), n_i, n_j))
    weights = np.zeros((n_taps, len(freqs), n_j))
    out = np.zeros((len(errors), n_j))
    for n, e in enumerate(errors):
        for k in range(len(freqs)):
            for i in range(n_i):
                for j in range(n_j):
                    r[n, k, i, j] = sum(paths[i, j, tap] * x(k, n - tap)
                                        for tap in range(n_l))
        if n >= n_l + n_taps - 1:
            for m in range(n_taps):
                for k in range(len(freqs)):
                    for j in range(n_j):
                        weights[m, k, j] -= mu * sum(e[i] * r[n - m, k, i, j]
                                                     for i in range(n_i))
        for j in range(n_j):
            out[n, j] = sum(weights[m, k, j] * x(k, n - m)
                            for m in range(n_taps) for k in range(len(freqs)))
    return out, weights


def test_vectorized_step_matches_explicit_loops_across_history_wraps():
    """Same outputs and weights as the textbook loops, to 1e-12.

    400 samples: the sliding histories wrap at sample 257 and the phasors re-synchronise
    every 256 samples.
    """
    rng = np.random.default_rng(7)
    paths = 0.1 * rng.standard_normal((2, 3, 32)) * np.exp(-np.arange(32) / 6.0)
    freqs, mu, n_taps = [40.0, 123.0], 0.2, 4
    errors = rng.standard_normal((400, 2))
    ctl = FilteredXLMSController(paths, freqs, FS, mu=mu, n_taps=n_taps)
    got = np.array([ctl.step(e) for e in errors])
    expected, weights = _reference_fxlms(paths, freqs, mu, n_taps, errors)
    assert np.max(np.abs(got - expected)) < 1e-12 * max(1.0, np.max(np.abs(expected)))
    np.testing.assert_allclose(ctl.weights, weights, rtol=0, atol=1e-12)


def test_core_loop_rejects_identification_overlapping_the_uncontrolled_window():
    sc = table1.table1_scenario(quick=True)
    config = load_model_config(config_path("pph_model.yaml"), sc.model_overrides)
    with pytest.raises(ValueError, match="overlap"):
        FxlmsCoreLoop(config, dataclasses.replace(sc, control_on_s=6.5, window_s=2.0))


# ----------------------------------------------------------------------------- benchmark
def _report(*tones):
    """A suppression report with (attenuation dB, floor-limited) at 40 and 80 Hz."""
    return {"tones": {f: {"attenuation_db": a, "floor_limited": fl}
                      for f, (a, fl) in zip(("40", "80"), tones, strict=True)}}


def test_equal_attenuation_counts_floor_limited_tones_as_equal():
    notch = _report((80.0, True), (50.0, True))
    assert table1.equal_attenuation(notch, _report((70.0, True), (45.0, True)), ["40", "80"])
    assert table1.equal_attenuation(notch, _report((78.0, False), (49.0, False)), ["40", "80"])
    assert not table1.equal_attenuation(notch, _report((76.0, False), (50.0, True)),
                                       ["40", "80"])
    assert not table1.equal_attenuation(notch, _report((90.0, True), (20.0, False)),
                                       ["40", "80"])


def test_linear_fit_exact_line():
    fit = costs.linear_fit([1, 2, 4, 8], [3.0, 5.0, 9.0, 17.0])
    assert fit["slope"] == pytest.approx(2.0)
    assert fit["intercept"] == pytest.approx(1.0)
    assert fit["r2"] == pytest.approx(1.0)


def _positive_finite(x):
    return isinstance(x, int | float) and math.isfinite(x) and x > 0


def test_bench_quick_writes_positive_finite_numbers(tmp_path, capsys):
    # --skip-sweep: the sweep's Dask cluster (~15 s here) is exercised by test/sweep
    assert cli.main(["--out", str(tmp_path), "--quick", "--skip-ros", "--skip-sweep"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    assert "sweep_throughput" not in results
    summary = (tmp_path / "summary.md").read_text()
    assert summary in capsys.readouterr().out
    assert "realtime" not in results and "lockstep_speedup" not in results
    for key in ("notch_us_per_sample", "notch_centralized_us_per_sample"):
        assert set(results[key]) == {"6x1", "6x2", "6x4", "6x8", "6x16"}
        assert all(_positive_finite(v) for v in results[key].values())
    for key in ("fxlms_us_per_sample", "cost_ratio_fxlms_over_notch_6x8",
                "cost_ratio_fxlms_over_notch_6x2"):
        assert _positive_finite(results[key])
    assert isinstance(results["equal_attenuation"], bool)
    targets = results["targets"]
    assert targets["cost_ratio_6x8"] == results["cost_ratio_fxlms_over_notch_6x8"]
    assert targets["cost_ratio_met"] == (targets["cost_ratio_6x8"] >= 10.0
                                         and results["equal_attenuation"])
    assert "## Issue targets" in summary
    floor = results["numpy_floor_us_per_sample"]
    assert _positive_finite(floor)
    assert targets["numpy_cost_ratio_bound"] == pytest.approx(max(
        *results["scaling"]["fxlms_vs_path_taps"]["us_per_sample"].values(),
        *results["fxlms_8tones_us_per_sample"].values()) / floor)
    compiled = results["compiled"]
    assert set(compiled["notch_us_per_sample"]) == {"6x1", "6x2", "6x4", "6x8", "6x16"}
    for key in ("fxlms_us_per_sample", "fxlms_8tones_us_per_sample"):
        assert set(compiled[key]) == {"32", "64", "128"}
        assert all(_positive_finite(v) for v in compiled[key].values())
    assert compiled["cost_ratio_fxlms_over_notch_6x8"] == pytest.approx(
        compiled["fxlms_us_per_sample"]["64"] / compiled["notch_us_per_sample"]["6x8"])
    assert all(d < 1e-12 for d in compiled["max_relative_difference_vs_numpy"].values())
    assert targets["compiled_cost_ratio_met"] == (
        compiled["cost_ratio_fxlms_over_notch_6x8"] >= 10.0 and results["equal_attenuation"])
    assert "## Controller cost per sample, compiled" in summary
    for name in ("notch", "fxlms"):
        assert set(results["attenuation_db"][name]) == {"40", "80"}
        assert all(_positive_finite(v) for v in results["attenuation_db"][name].values())
        assert _positive_finite(results["convergence_s"][name])
    scaling = results["scaling"]
    assert set(scaling["notch_vs_channels"]["us_per_sample"]) == {"1", "2", "3", "6", "12"}
    assert set(scaling["fxlms_vs_path_taps"]["us_per_sample"]) == {"32", "64", "128"}
    for sweep in ("notch_vs_tones", "notch_vs_tones_large", "notch_vs_channels",
                  "fxlms_vs_path_taps"):
        assert all(_positive_finite(v) for v in scaling[sweep]["us_per_sample"].values())
        fit = next(v for k, v in scaling[sweep].items() if k.startswith("fit_"))
        assert set(fit) == {"slope", "intercept", "r2"}
        assert all(math.isfinite(v) for v in fit.values())
    machine = results["machine_details"]
    assert machine["cpu_count"] >= 1 and machine["python"] and machine["numpy"]
    assert isinstance(results["machine"], str) and machine["python"] in results["machine"]
