"""Moving tones in the report: a band that follows each tone, frequencies and sensitivity."""

from __future__ import annotations

import json

import numpy as np
import pytest
from bag_factory import (
    FS,
    array_cdr,
    frequencies_cdr,
    notch_status,
    struts_from_z,
    tone,
    write_bag,
)

from hexapod_vibration.analysis import moving_tones
from hexapod_vibration.analysis.levels import tone_levels
from hexapod_vibration.analysis.run_record import RunRecord
from hexapod_vibration.core.spectrum import G0
from hexapod_vibration.tools import analyze

LEVEL_DB = -37.0


def drifting_tone(level_db: float, f_hz: float, drift_hz: float, period_s: float, n: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(signal, frequency per sample): the shaker's drift, f + df sin(2 pi t / T)."""
    t = np.arange(n) / FS
    phase = 2 * np.pi * f_hz * t - drift_hz * period_s * np.cos(2 * np.pi * t / period_s)
    amplitude = np.sqrt(2.0) * G0 * 10 ** (level_db / 20.0)
    return amplitude * np.sin(phase), f_hz + drift_hz * np.sin(2 * np.pi * t / period_s)


def ramp_tone(level_db: float, f0_hz: float, rate_hz_s: float, n: int, order: float = 1.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """(signal, frequency per sample) of order ``order`` of a speed f0 + rate t."""
    t = np.arange(n) / FS
    amplitude = np.sqrt(2.0) * G0 * 10 ** (level_db / 20.0)
    phase = 2 * np.pi * order * (f0_hz * t + 0.5 * rate_hz_s * t**2)
    return amplitude * np.sin(phase), order * (f0_hz + rate_hz_s * t)


def following_level(x: np.ndarray, track_hz: np.ndarray) -> float:
    y, f_ref = moving_tones.dechirp(x, track_hz, FS)
    return tone_levels(y, [f_ref])[0][0]


def test_a_steady_track_leaves_the_signal_and_its_level_unchanged():
    x = tone(LEVEL_DB, 40.0, 10_000) + 1e-6 * np.random.default_rng(1).standard_normal(10_000)
    y, f_ref = moving_tones.dechirp(x, np.full(10_000, 40.0), FS)
    assert f_ref == 40.0 and np.array_equal(y, x)
    assert following_level(x, np.full(10_000, 40.0)) == tone_levels(x, [40.0])[0][0]


def test_the_band_follows_a_drifting_tone():
    rng = np.random.default_rng(2)
    x, track = drifting_tone(LEVEL_DB, 40.0, 1.0, 20.0, 15_000)
    x, track = x[5000:] + 1e-5 * rng.standard_normal(10_000), track[5000:]   # 41 -> 39 Hz
    assert following_level(x, track) == pytest.approx(LEVEL_DB, abs=0.2)
    fixed = tone_levels(x, [float(np.mean(track))])[0][0]
    assert fixed < LEVEL_DB - 1.0          # part of the energy lies outside the fixed band


def test_the_band_follows_one_order_of_a_spin_up_beside_the_next():
    rng = np.random.default_rng(3)
    first, track = ramp_tone(LEVEL_DB, 30.0, 1.0, 10_000)
    second, _ = ramp_tone(LEVEL_DB + 6.0, 30.0, 1.0, 10_000, order=2.0)
    x = first + second + 1e-5 * rng.standard_normal(10_000)
    assert following_level(x, track) == pytest.approx(LEVEL_DB, abs=0.3)
    # A track read every 10 samples and interpolated gives the same level.
    coarse = moving_tones.track_on_samples(np.arange(0, 10_000, 10), track[::10],
                                           np.arange(10_000))
    assert following_level(x, coarse) == pytest.approx(following_level(x, track), abs=0.01)


def test_columns_are_matched_to_the_nearest_tone_once_and_within_tolerance():
    table = np.array([[40.2, 30.0, 60.0], [40.4, 31.0, 62.0]])
    assert moving_tones.match_columns(table, [40.0, 61.0, 100.0]) == [0, 2, None]
    assert moving_tones.match_columns(table, [40.0, 40.3]) == [None, 0]


def test_the_measured_ratio_of_a_halved_signal_is_minus_6db():
    x = np.random.default_rng(4).standard_normal(20_000)
    f, ratio = moving_tones.spectrum_ratio_db(0.5 * x, x, FS)
    assert ratio == pytest.approx(np.full(f.size, 20 * np.log10(0.5)), abs=1e-9)


# ---------------------------------------------------------------- through analyze
ON, END = 12_000, 24_000


def _drift_bag(tmp_path, sensitivity: bool, notch_tones=(40.0,)):
    """A 40 Hz tone drifting +-1 Hz (20 s) reduced 60 dB from 3.5 s after control-on.

    ``notch_tones``: the notch's ``tones_hz`` on /diagnostics (tracked ones move).
    """
    rng = np.random.default_rng(5)
    x, track = drifting_tone(LEVEL_DB, 40.0, 1.0, 20.0, END)
    n = np.arange(END)
    gain = np.where(n < ON, 1.0, np.maximum(np.exp(-(n - ON) / 500.0), 1e-3))
    z = G0 + gain * x + 1e-6 * rng.standard_normal(END)
    statuses = [(s, notch_status(s, "adapting" if s >= ON else "disabled", list(notch_tones),
                                 ON if s >= ON else -1, (500, 1500))) for s in range(0, END, 1000)]
    topics = {
        "/pph/disturbance_frequencies": [(s, frequencies_cdr([25.0, track[s]], s))
                                         for s in range(0, END, 10)],
        "/pph/notch_frequencies": [(s, frequencies_cdr([40.0 + 0.9 * (track[s] - 40.0)], s))
                                   for s in range(0, END, 10)]}
    if sensitivity:
        grid = np.linspace(0.0, 500.0, 5001)
        predicted = np.where(np.abs(grid - 40.0) < 0.5, -20.0, 0.0)
        topics["/pph/notch_sensitivity"] = [(1600, array_cdr(
            np.vstack([grid, predicted, predicted + 0.5]),
            [("rows:frequency_hz,sigma_max_db,output_db", 3, 3 * grid.size),
             ("frequency", grid.size, 1), ("sample:1600", 1, 1)]))]
    record = RunRecord(scenario="drift_test", report_tones_hz=[40.0], notch_tones_hz=[40.0],
                       window_s=10.0, samples=END, control_on_sample=ON,
                       identify_at_sample=500, identification_samples=1000)
    return write_bag(tmp_path / "bag", struts_from_z(z), statuses=statuses,
                     run_record=record.to_json(), topics=topics)


def test_report_follows_the_drifting_tone_from_the_true_frequency(tmp_path, capsys):
    bag = _drift_bag(tmp_path, sensitivity=False)
    assert analyze.main([str(bag), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    assert "bands following the tones" in capsys.readouterr().out
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    fixed = report["tones"][0]
    row, = report["following_tones"]
    assert row["source"] == "/pph/disturbance_frequencies"
    assert row["uncontrolled_db"] == pytest.approx(LEVEL_DB, abs=0.3)
    assert row["reduction_db"] == pytest.approx(60.0, abs=0.5)
    assert fixed["uncontrolled_db"] < LEVEL_DB - 3.0     # the fixed band misses most of it
    _, track = drifting_tone(LEVEL_DB, 40.0, 1.0, 20.0, END)
    window = track[ON - 9999:ON]                  # the report's (after the identification)
    assert row["frequency_span_hz"]["uncontrolled"] == pytest.approx(
        [window.min(), window.max()], abs=1e-3)
    assert "sensitivity" not in report


def test_report_compares_the_recorded_prediction_and_plots_both(tmp_path):
    bag = _drift_bag(tmp_path, sensitivity=True)
    assert analyze.main([str(bag), "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    sens = report["sensitivity"]
    assert sens["view"] == "output" and sens["prediction_sample"] == 1600
    assert sens["predicted_rise_db"] == pytest.approx(0.5)
    # the tone drifted +-1 Hz over the windows: a fixed-tone prediction is not compared
    assert sens["near_tones_points"] == 0 and sens["near_tones_rms_difference_db"] is None
    assert sens["not_compared"].startswith("the notch ran up to 0.9")
    for png in ("frequencies.png", "sensitivity.png"):
        assert (tmp_path / "out" / png).stat().st_size > 10_000


def test_a_tracked_notch_tone_is_its_reported_tone_and_keeps_its_nominal_label(tmp_path):
    """The diagnostics' tones_hz of a tracking notch end a few mHz off the reported tone."""
    from hexapod_vibration.analysis.following import snap_to_tones

    assert snap_to_tones([40.398966, 80.0, 55.0], [40.4, 80.02, 60.0]) == [40.4, 80.02, 55.0]
    bag = _drift_bag(tmp_path, sensitivity=False, notch_tones=(39.9831,))
    assert analyze.main([str(bag), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["tones"][0]["controlled"] is True
    assert report["following_tones"][0]["frequency_hz"] == 40.0       # the run record's
