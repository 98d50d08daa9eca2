"""A run against its uncontrolled twin: H1 sensitivity, the twin check, ``analyze --twin``.

Synthetic signals (no ROS): the twin is a tone plus broadband noise; the run is the same
signal, and from control-on the same signal through a known LTI filter (a notch: the
sensitivity of a canceller at the tone), or a drifting tone removed by a decaying gain.
"""

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
from scipy import signal

from hexapod_vibration.analysis import moving_tones, twin
from hexapod_vibration.analysis.run_record import RunRecord
from hexapod_vibration.core.spectrum import G0
from hexapod_vibration.tools import analyze

ON, END = 12_000, 24_000
NOISE_M_S2 = 3e-3
NOTCH_HZ, POLE_RADIUS = 40.0, 0.99


def notch_filter() -> tuple[np.ndarray, np.ndarray]:
    """(b, a): a notch at 40 Hz, |H| from 0 dB far from it to a zero at it."""
    w0 = 2 * np.pi * NOTCH_HZ / FS
    b = np.array([1.0, -2.0 * np.cos(w0), 1.0])
    a = np.array([1.0, -2.0 * POLE_RADIUS * np.cos(w0), POLE_RADIUS**2])
    return b, a


def response_db(b, a, f_hz: np.ndarray) -> np.ndarray:
    _, h = signal.freqz(b, a, worN=f_hz, fs=FS)
    return 20 * np.log10(np.abs(h))


def test_the_h1_estimate_is_the_filters_response():
    rng = np.random.default_rng(1)
    x = rng.standard_normal(20_000) + 0.3 * np.sin(2 * np.pi * 100.0 * np.arange(20_000) / FS)
    b, a = signal.butter(2, 60.0, fs=FS)
    y = signal.lfilter(b, a, x)
    f, h1_db, coherence = moving_tones.transfer_function_db(x, y, FS)
    band = (f >= 5.0) & (f <= 150.0)
    assert np.max(np.abs(h1_db[band] - response_db(b, a, f[band]))) < 0.5
    assert np.min(coherence[band]) > 0.99


def test_bands_rise_with_a_gain_and_never_worse_fails_above_1db():
    x = np.random.default_rng(2).standard_normal(10_000)
    same = twin._bands(x, x)
    assert same["largest_rise_db"] == 0.0 and same["never_worse"] is True
    louder = twin._bands(1.5 * x, x)
    assert louder["largest_rise_db"] == pytest.approx(20 * np.log10(1.5), abs=0.01)
    assert louder["never_worse"] is False


# ---------------------------------------------------------------- through analyze
def _record(name: str, on: int, tones: tuple[float, ...] = (40.0, 80.0)) -> str:
    return RunRecord(scenario=name, report_tones_hz=list(tones), notch_tones_hz=[40.0],
                     window_s=10.0, samples=END, control_on_sample=on,
                     identify_at_sample=500, identification_samples=1000).to_json()


def _statuses(on: int) -> list[tuple[int, dict[str, str]]]:
    return [(s, notch_status(s, "adapting" if 0 <= on <= s else "disabled", [40.0],
                             on if 0 <= on <= s else -1, (500, 1500)))
            for s in range(0, END, 1000)]


def _prediction(b, a) -> dict[str, list[tuple[int, bytes]]]:
    grid = np.linspace(0.0, 500.0, 5001)
    predicted = response_db(b, a, grid[1:])
    predicted = np.concatenate([[predicted[0]], predicted])
    return {"/pph/notch_sensitivity": [(1600, array_cdr(
        np.vstack([grid, predicted, predicted]),
        [("rows:frequency_hz,sigma_max_db,output_db", 3, 3 * grid.size),
         ("frequency", grid.size, 1), ("sample:1600", 1, 1)]))]}


def _lti_pair(tmp_path, twin_seed: int = 3, twin_end: int = END,
              track_span_hz: float | None = None):
    """(run bag, twin bag): 40 and 80 Hz tones in noise; the run filtered from ON.

    ``twin_seed`` other than 3 or ``twin_end`` short of END: a bag that is not the twin.
    ``track_span_hz``: the notch's recorded oscillator frequency (``/pph/notch_frequencies``),
    ramping from 40 Hz over this span (Hz) across the controlled window (the signal itself
    stays as it is).
    """
    def uncontrolled(seed: int) -> np.ndarray:
        noise = NOISE_M_S2 * np.random.default_rng(seed).standard_normal(END)
        return tone(-40.0, 40.0, END) + tone(-50.0, 80.0, END) + noise

    b, a = notch_filter()
    x_run, x = uncontrolled(3), uncontrolled(twin_seed)
    y = np.where(np.arange(END) < ON, x_run, signal.lfilter(b, a, x_run))
    topics = _prediction(b, a)
    if track_span_hz is not None:
        track = 40.0 + track_span_hz * np.clip((np.arange(END) - (END - 10_000)) / 10_000,
                                               0.0, 1.0)
        topics["/pph/notch_frequencies"] = [(s, frequencies_cdr([track[s]], s))
                                            for s in range(0, END, 10)]
    run = write_bag(tmp_path / "bag", struts_from_z(G0 + y), statuses=_statuses(ON),
                    run_record=_record("lti", ON), topics=topics)
    twin_bag = write_bag(tmp_path / "twin", struts_from_z(G0 + x[:twin_end]),
                         statuses=_statuses(-1)[:twin_end // 1000],
                         run_record=_record("lti", -1), topics=topics)
    return run, twin_bag


def _decaying_pair(tmp_path, name: str, x: np.ndarray, tracks: np.ndarray,
                   tones: list[float], seed: int, residual: float = 1e-3,
                   burst: np.ndarray | None = None):
    """(run bag, twin bag): ``x`` (m/s^2, z) in noise; in the run it decays 60 dB from ON.

    ``tracks`` (END, L): the true line frequencies recorded on /pph/disturbance_frequencies.
    ``residual``: the gain the run's ``x`` decays to (0: removed, down to the noise floor).
    ``burst``: (END,) m/s^2 added to the run only (something control did).
    """
    n = np.arange(END)
    noise = 1e-6 * np.random.default_rng(seed).standard_normal(END)
    gain = np.where(n < ON, 1.0, np.maximum(np.exp(-(n - ON) / 500.0), residual))
    added = np.zeros(END) if burst is None else burst
    topics = {"/pph/disturbance_frequencies": [(s, frequencies_cdr(list(tracks[s]), s))
                                               for s in range(0, END, 10)]}
    run = write_bag(tmp_path / "bag", struts_from_z(G0 + gain * x + noise + added),
                    statuses=_statuses(ON), run_record=_record(name, ON, tones),
                    topics=topics)
    other = write_bag(tmp_path / "twin", struts_from_z(G0 + x + noise),
                      statuses=_statuses(-1), run_record=_record(name, -1, tones),
                      topics=topics)
    return run, other


def test_analyze_against_the_twin_measures_the_filter(tmp_path, capsys):
    run, twin_bag = _lti_pair(tmp_path)
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(twin_bag), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "against its twin" in printed and "never worse than off: yes" in printed
    report = json.loads((out / "report.json").read_text())
    assert {"scenario", "tones", "convergence_s", "loop", "sensitivity"} <= set(report)
    section = report["twin"]
    assert section["window"] == {"first_sample": END - 10_000, "samples": 10_000}
    rows = {r["frequency_hz"]: r for r in section["tones"]}
    assert rows[40.0]["band"] == "fixed" and rows[40.0]["twin_db"] == pytest.approx(-40, abs=.3)
    assert rows[40.0]["reduction_db"] > 40.0               # the notch's zero is at 40 Hz
    expected_80 = -response_db(*notch_filter(), np.array([80.0]))[0]
    assert rows[80.0]["reduction_db"] == pytest.approx(expected_80, abs=0.2)
    assert section["bands"]["never_worse"] is True
    assert section["bands"]["largest_rise_db"] < 0.2
    sens = section["sensitivity"]
    assert sens["near_tones_points"] > 20
    assert sens["near_tones_rms_difference_db"] < 0.5       # the twin removes the scatter
    assert sens["near_tones_max_difference_db"] < 1.0
    assert section["following_over_time"] == []            # no frequency track recorded
    assert (out / "sensitivity.png").stat().st_size > 10_000


@pytest.mark.parametrize("what", ["other_noise", "shorter"])
def test_a_bag_that_is_not_the_twin_is_refused_in_one_line(tmp_path, capsys, what):
    run, other = _lti_pair(tmp_path, **({"twin_seed": 4} if what == "other_noise"
                                         else {"twin_end": END - 1000}))
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(other), "--out", str(out),
                         "--no-plots"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "is not this run's twin" in err, err
    assert ("differs" if what == "other_noise" else "samples") in err
    assert not out.exists()


def test_a_drifting_tone_is_followed_over_time_against_the_twin(tmp_path, capsys):
    """40 Hz drifting +-1 Hz (20 s period); the run's tone decays 60 dB from control-on."""
    x, track = _drifting_40_hz()
    run, other = _decaying_pair(tmp_path, "drift", x, track[:, None], [40.0], seed=5)
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(other), "--out", str(out), "--no-plots",
                         "--twin-segment", "2"]) == 0
    printed = capsys.readouterr().out
    assert "following 40 Hz over 2 s windows" in printed
    section = json.loads((out / "report.json").read_text())["twin"]
    row, = section["tones"]
    assert row["band"] == "following" and row["source"] == "/pph/disturbance_frequencies"
    assert row["twin_db"] == pytest.approx(-37.0, abs=0.3)
    assert row["reduction_db"] == pytest.approx(60.0, abs=0.5)
    over, = section["following_over_time"]
    starts = [p[0] for p in over["reduction_db"]]
    assert starts == [12.0, 14.0, 16.0, 18.0, 20.0, 22.0]
    assert over["reduction_db"][0][1] < 40.0                 # the decay at control-on
    assert over["reduction_db"][-1][1] == pytest.approx(60.0, abs=0.5)
    assert over["median_reduction_db"] == pytest.approx(60.0, abs=0.5)
    assert over["min_reduction_db"] == over["reduction_db"][0][1]


def _drifting_40_hz() -> tuple[np.ndarray, np.ndarray]:
    """(x m/s^2 at -37 dB re 1 g, track Hz): 40 Hz drifting +-1 Hz with a 20 s period."""
    t = np.arange(END) / FS
    phase = 2 * np.pi * 40.0 * t - 1.0 * 20.0 * np.cos(2 * np.pi * t / 20.0)
    track = 40.0 + np.sin(2 * np.pi * t / 20.0)
    return np.sqrt(2) * G0 * 10 ** (-37 / 20) * np.sin(phase), track


def test_windows_at_the_noise_floor_are_flagged_and_their_reduction_is_a_bound(tmp_path,
                                                                              capsys):
    """A drifting tone removed entirely: its last windows are flagged as noise floor.

    The run's tone decays 17.4 dB/s from control-on down to nothing: the last 2 s windows
    read the controlled level at its noise floor, so their reductions say only how far the
    floor lies below the line.
    """
    x, track = _drifting_40_hz()
    run, other = _decaying_pair(tmp_path, "drift", x, track[:, None], [40.0], seed=5,
                                residual=0.0)
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(other), "--out", str(out), "--no-plots",
                         "--twin-segment", "2"]) == 0
    printed = capsys.readouterr().out
    over, = json.loads((out / "report.json").read_text())["twin"]["following_over_time"]
    floor = over["at_noise_floor"]
    assert floor["twin"] == [False] * 6
    assert floor["controlled"][:2] == [False, False] and floor["controlled"][-1] is True
    assert over["windows_at_floor"] == sum(floor["controlled"]) >= 1
    first = over["reduction_db"][0][1]
    assert over["min_measured_reduction_db"] == first < 40.0
    assert all(p[1] > 100.0 for p, at in zip(over["reduction_db"], floor["controlled"],
                                             strict=True) if at)
    assert (f"{over['windows_at_floor']} at the noise floor; above it: min {first:.1f} dB"
            in printed)


def test_a_minimum_at_the_noise_floor_is_printed_as_a_bound():
    """The console line of a tone whose smallest reduction is a floor-limited bound."""
    tone = {"frequency_hz": 90.0, "segment_s": 1.0,
            "reduction_db": [[13.0, 11.4], [14.0, 27.0], [15.0, 44.0]],
            "at_noise_floor": {"controlled": [False, True, True], "twin": [False] * 3},
            "min_reduction_db": 11.4, "median_reduction_db": 27.0,
            "min_measured_reduction_db": 11.4, "windows_at_floor": 2}
    line = twin._over_time_line(tone)
    assert line == ("following 90 Hz over 1 s windows from control-on: min 11.4 dB, median "
                    "27.0 dB (3 windows, 2 at the noise floor; above it: min 11.4 dB)")
    tone["reduction_db"][0][1] = tone["min_reduction_db"] = 30.0
    tone["at_noise_floor"]["controlled"][0] = True
    tone.update(min_measured_reduction_db=None, windows_at_floor=3)
    tone["reduction_db"][1][1] = tone["min_reduction_db"] = 27.0
    assert twin._over_time_line(tone).endswith(
        "min >= 27.0 dB, median 27.0 dB (3 windows, 3 at the noise floor; above it: none)")


def test_never_worse_is_judged_in_every_window_from_control_on(tmp_path, capsys):
    """A burst before the report's window is caught by the sliding windows.

    Noise added 0.5 s after control-on, before the report's window (the last 10 s): the
    report's own window is never worse, the sliding windows that hold the burst are not.
    """
    x, track = _drifting_40_hz()
    n = np.arange(END)
    burst = np.where((n >= ON + 500) & (n < ON + 1000),
                     1e-4 * np.random.default_rng(9).standard_normal(END), 0.0)
    run, other = _decaying_pair(tmp_path, "drift", x, track[:, None], [40.0], seed=5,
                                burst=burst)
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(other), "--out", str(out), "--no-plots"]) == 0
    printed = capsys.readouterr().out
    section = json.loads((out / "report.json").read_text())["twin"]
    assert section["bands"]["never_worse"] is True
    sliding = section["bands_over_time"]
    assert sliding["window_s"] == 10.0 and sliding["start_s"] == [12.0, 13.0, 14.0]
    assert sliding["worst_start_s"] == 12.0 and sliding["worst_rise_db"] > 10.0
    assert sliding["never_worse"] is False
    assert sliding["largest_rise_db"][2] == section["bands"]["largest_rise_db"]
    assert "in every 10 s window from control-on (step 1 s): worst" in printed
    assert "12-22 s (never worse than off: NO)" in printed


def test_a_moving_tone_is_not_compared_with_a_fixed_tone_prediction(tmp_path, capsys):
    """The LTI pair with a recorded frequency track: fixed, compared; drifting, not."""
    for span_hz, compared in ((0.0, True), (1.5, False)):
        run, twin_bag = _lti_pair(tmp_path / f"span{span_hz}", track_span_hz=span_hz)
        out = tmp_path / f"out{span_hz}"
        assert analyze.main([str(run), "--twin", str(twin_bag), "--out", str(out),
                             "--no-plots"]) == 0
        printed = capsys.readouterr().out
        sens = json.loads((out / "report.json").read_text())["twin"]["sensitivity"]
        assert (sens["near_tones_points"] > 20) is compared
        assert ("not_compared" in sens) is not compared
        assert ("H1 not compared" in printed) is not compared
        if not compared:
            assert sens["not_compared"].startswith("the notch ran up to 1.50 Hz from the tones")


def _ramp_40_to_43_hz() -> np.ndarray:
    """(END,) Hz: 40 Hz until ON, 3 Hz/s to 43 Hz, then held (a spin-up's end)."""
    return 40.0 + 3.0 * np.clip((np.arange(END) - ON) / 1000.0, 0.0, 1.0)


def test_a_tone_held_away_from_its_report_tone_is_measured_where_it_is(tmp_path):
    """A spin-up's end: the line ramps 40 -> 43 Hz after control-on and holds at 43 Hz.

    Over the controlled window the track does not move, but it is not at the report tone
    (40 Hz): the twin row follows it (a fixed band at 40 Hz would read the noise floor).
    """
    track = _ramp_40_to_43_hz()
    x = np.sqrt(2) * G0 * 10 ** (-37 / 20) * np.sin(2 * np.pi * np.cumsum(track) / FS)
    run, other = _decaying_pair(tmp_path, "held", x, track[:, None], [40.0], seed=6)
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(other), "--out", str(out), "--no-plots"]) == 0
    row, = json.loads((out / "report.json").read_text())["twin"]["tones"]
    assert row["band"] == "following" and row["frequency_span_hz"] == [43.0, 43.0]
    assert row["twin_db"] == pytest.approx(-37.0, abs=0.3)
    assert row["reduction_db"] == pytest.approx(60.0, abs=0.5)


def test_a_second_line_that_started_on_a_report_tone_is_followed_there(tmp_path):
    """A rotor's order 2 (in the bank, not a notch tone): 80 -> 86 Hz, reported at 80 Hz."""
    track = _ramp_40_to_43_hz()
    phase = 2 * np.pi * np.cumsum(track) / FS
    x = np.sqrt(2) * G0 * 10 ** (-37 / 20) * (np.sin(phase) + 0.5 * np.sin(2 * phase))
    run, other = _decaying_pair(tmp_path, "orders", x, np.column_stack([track, 2 * track]),
                                [40.0, 80.0], seed=7)
    out = tmp_path / "out"
    assert analyze.main([str(run), "--twin", str(other), "--out", str(out), "--no-plots"]) == 0
    rows = {r["frequency_hz"]: r for r in json.loads((out / "report.json").read_text())[
        "twin"]["tones"]}
    assert set(rows) == {40.0, 80.0}
    assert rows[80.0]["band"] == "following" and rows[80.0]["frequency_span_hz"] == [86.0, 86.0]
    assert rows[80.0]["controlled"] is False                 # not a notch tone
    assert rows[80.0]["twin_db"] == pytest.approx(-37.0 - 6.02, abs=0.3)
    assert rows[80.0]["reduction_db"] == pytest.approx(60.0, abs=0.5)
