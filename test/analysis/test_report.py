"""The report from hand-made bags with known content: levels, windows, samples, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
from bag_factory import (
    FS,
    notch_status,
    strut_cdr,
    struts_from_z,
    tone,
    write_bag,
)

from hexapod_vibration.analysis.run_record import RunRecord
from hexapod_vibration.bench import table1
from hexapod_vibration.core import spectrum
from hexapod_vibration.core.spectrum import G0
from hexapod_vibration.tools import analyze

CLOSE = [37.0, 38.0, 39.0, 40.0, 41.0, 42.0]
PAPER = {"37": -8.0, "38": -11.6, "39": 60.1, "40": 59.1, "41": -1.0, "42": -4.8}
ON, END, TAU_S = 16000, 36000, 0.5


def close_tones_z(seed: int = 1) -> np.ndarray:
    """1 g + 39 and 40 Hz at -37 dB, both decaying by exp(-t/0.5 s) after control-on."""
    rng = np.random.default_rng(seed)
    n = np.arange(END)
    decay = np.where(n < ON, 1.0, np.exp(-(n - ON) / (TAU_S * FS)))
    z = G0 + decay * (tone(-37.0, 39.0, END) + tone(-37.0, 40.0, END, 0.7))
    return z + 1e-6 * rng.standard_normal(END)     # floor about -140 dB in 0.9 Hz


def record(**changes) -> str:
    base = dict(scenario="close_tones", report_tones_hz=CLOSE, notch_tones_hz=[39.0, 40.0],
                window_s=10.0, samples=END, control_on_sample=ON, identify_at_sample=1000,
                identification_samples=3200, paper_reduction_db=PAPER)
    base.update(changes)
    return RunRecord(**base).to_json()


def statuses(tones=(39.0, 40.0), ident=(1000, 4199), keys=True):
    """Notch statuses every second, with the identification as the controller reports it."""
    out = []
    for sample in range(0, END, 1000):
        state = ("identifying" if ident[0] <= sample <= ident[1] else
                 "adapting" if sample >= ON else "disabled")
        out.append((sample, notch_status(sample, state, list(tones),
                                         ON if sample >= ON else -1,
                                         ident if keys and sample >= ident[0] else
                                         ((-1, -1) if keys else None))))
    return out


def run_analyze(bag, out, *args):
    code = analyze.main([str(bag), "--out", str(out), "--no-plots", *args])
    report = json.loads((out / "report.json").read_text()) if code == 0 else None
    details = json.loads((out / "details.json").read_text()) if code == 0 else None
    return code, report, details


# ---------------------------------------------------------------- level over time
def test_convergence_is_not_fooled_by_gravity_and_matches_the_known_decay(tmp_path):
    """A 0.5 s boxcar envelope would let 1 g leak into 39 Hz (a 'convergence' in 0.01 s)."""
    bag = write_bag(tmp_path / "bag", struts_from_z(close_tones_z()), statuses=statuses(),
                    run_record=record())
    code, report, details = run_analyze(bag, tmp_path / "out")
    assert code == 0
    # exp(-t/tau) from -37 dB to the floor: within 3 dB of the final level (mean power of
    # the last 2 s) at about tau ln(amplitude ratio); the 4.5 s level window (1 Hz
    # neighbours) averages a decaying tone, which delays that by at most a second.
    final = {f: details["convergence"][f]["final_level_db"] for f in ("39", "40")}
    for f in ("39", "40"):
        expected = TAU_S * np.log(10 ** ((-37.0 - final[f] - 3.0) / 20.0))
        got = details["convergence"][f]["convergence_s"]
        assert expected - 0.3 <= got <= expected + 1.2, (f, got, expected)
        assert final[f] < -100.0
    assert report["convergence_s"] == pytest.approx(
        max(details["convergence"][f]["convergence_s"] for f in ("39", "40")), abs=1e-6)


def test_the_benchmark_uses_the_same_convergence_definition():
    z = close_tones_z()
    ours = spectrum.tone_convergence(z, FS, 40.0, ON, other_hz=CLOSE)
    bench = table1.tone_convergence_s(z, FS, 40.0, ON / FS, CLOSE)
    assert bench["convergence_s"] == ours["convergence_s"]
    assert bench["final_level_db"] == ours["final_level_db"]


# ---------------------------------------------------------------- the run record
def test_analyze_reports_what_the_run_recorded(tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", struts_from_z(close_tones_z()), statuses=statuses(),
                    run_record=record())
    code, report, details = run_analyze(bag, tmp_path / "out")
    assert code == 0
    assert report["scenario"] == "close_tones"
    assert [r["frequency_hz"] for r in report["tones"]] == CLOSE
    assert details["windows"]["uncontrolled"]["first_sample"] == ON - 10000
    out = capsys.readouterr().out
    assert "paper reduction" in out and "60.1" in out
    # the floor (and so every level) does not depend on which other tones are asked for
    code, alone, _ = run_analyze(bag, tmp_path / "alone", "--tones", "39", "40")
    assert code == 0
    rows = {r["frequency_hz"]: r for r in report["tones"]}
    for row in alone["tones"]:
        assert row == rows[row["frequency_hz"]]


# ---------------------------------------------------------------- identification
@pytest.mark.parametrize("keys", [True, False], ids=["identification keys", "older bag"])
def test_windows_leave_out_the_identification(tmp_path, keys):
    """A 16 s window reaches into the identification's 80 Hz test tones: left out."""
    z = G0 + tone(-31.0, 40.0, END) + tone(-68.0, 80.0, END, 0.3)
    z[1000:4200] += tone(-40.0, 80.0, 3200)          # the identification's test tones
    bag = write_bag(tmp_path / "bag", struts_from_z(z),
                    statuses=statuses(tones=(40.0, 80.0), keys=keys))
    code, report, details = run_analyze(bag, tmp_path / "out", "--tones", "40", "80",
                                        "--window", "16")
    assert code == 0
    rows = {r["frequency_hz"]: r for r in report["tones"]}
    assert rows[80.0]["uncontrolled_db"] == pytest.approx(-68.0, abs=0.3)
    assert any("identification" in n for n in details["notes"])
    assert details["windows"]["uncontrolled"]["first_sample"] >= 4200


def test_a_window_left_too_short_is_refused_in_one_line(tmp_path, capsys):
    z = G0 + tone(-37.0, 39.0, END) + tone(-37.0, 40.0, END, 0.7)
    bag = write_bag(tmp_path / "bag", struts_from_z(z), statuses=statuses())
    code = analyze.main([str(bag), "--out", str(tmp_path / "out"), "--tones", "39", "40",
                         "--control-on", "6.0", "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "needs 9 s" in err and "identification" in err
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- counted from 0
def test_samples_are_counted_from_the_runs_sample_0(tmp_path):
    z = G0 + tone(-31.0, 40.0, END)
    index = np.arange(243, END)                      # the first 243 samples never arrived
    bag = write_bag(tmp_path / "bag", struts_from_z(z[243:]), index=index,
                    statuses=statuses(tones=(40.0,)))
    code, report, details = run_analyze(bag, tmp_path / "out", "--tones", "40")
    assert code == 0
    assert details["topics"]["/pph/accel"]["missing_samples"] == 243
    assert details["topics"]["/pph/accel"]["first_sample"] == 243
    assert report["loop"]["samples"] == END
    assert report["loop"]["missed_samples"] == 243


# ---------------------------------------------------------------- floor flags
def test_at_noise_floor_is_in_the_report_and_the_table(tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", struts_from_z(close_tones_z()), statuses=statuses(),
                    run_record=record())
    code, report, details = run_analyze(bag, tmp_path / "out")
    assert code == 0
    rows = {r["frequency_hz"]: r for r in report["tones"]}
    assert rows[40.0]["at_noise_floor"] == {"uncontrolled": False, "controlled": True}
    flags = details["levels_db_re_1g"]
    table = capsys.readouterr().out.splitlines()
    for k, f in enumerate(CLOSE):
        floor = rows[f]["at_noise_floor"]
        assert floor["uncontrolled"] == flags["uncontrolled"]["at_noise_floor"][k]
        assert floor["controlled"] == flags["controlled"]["at_noise_floor"][k]
        line = next(x for x in table if x.strip().startswith(f"{f:.1f}Hz"))
        assert line.count("(floor)") == floor["uncontrolled"] + floor["controlled"]
        # '>=': a lower bound only when the controlled level, not the uncontrolled, is floor
        assert (">=" in line) == (floor["controlled"] and not floor["uncontrolled"])


# ---------------------------------------------------------------- bad messages
def test_one_undecodable_message_is_skipped_and_counted(tmp_path):
    z = G0 + tone(-31.0, 40.0, 24000)
    good = strut_cdr(np.zeros(6), 5000)
    bad = [("/pph/accel", 5000, good[:-8]), ("/pph/accel", 7000, b"\xff" * 40),
           ("/pph/accel", 9000, good[:12])]
    bag = write_bag(tmp_path / "bag", struts_from_z(z), extra=bad)
    code, report, details = run_analyze(bag, tmp_path / "out", "--tones", "40")
    assert code == 0
    assert details["topics"]["/pph/accel"]["invalid_messages"] == 3
    assert report["tones"][0]["uncontrolled_db"] == pytest.approx(-31.0, abs=0.3)


def test_a_few_invalid_messages_do_not_give_wrong_levels_with_exit_0(tmp_path, capsys):
    """5-value messages in 1 % of the samples: no gap-free run long enough: refused."""
    z = G0 + tone(-37.0, 39.0, 24000) + tone(-37.0, 40.0, 24000, 0.7)
    index = np.arange(24000)
    keep = index % 100 != 50
    five = [("/pph/accel", int(n) - 1, strut_cdr(np.zeros(6), int(n))[:-8])
            for n in index[~keep]]
    bag = write_bag(tmp_path / "bag", struts_from_z(z)[keep], index=index[keep], extra=five)
    code = analyze.main([str(bag), "--out", str(tmp_path / "out"), "--tones", "39", "40",
                         "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "usable run is 0.099 s" in err


def test_memory_does_not_grow_with_the_messages_of_a_long_bag(tmp_path):
    """20 s of all five strut topics (100 000 messages), read within 10 MB.

    The analysis keeps ~70 bytes per accelerometer sample, not the messages (it took
    2.3 MB per second of bag before: 46 MB here).
    """
    import tracemalloc

    from rosbags.rosbag2 import StoragePlugin, Writer

    from hexapod_vibration.analysis.bag_format import BAG_VERSION, STRUT_MSGTYPE, STRUT_TOPICS
    from hexapod_vibration.analysis.bag_format import typestore as store
    from hexapod_vibration.analysis.bag_signals import load_signals
    from hexapod_vibration.analysis.report import Request, analyze_signals
    from hexapod_vibration.core.model.config import load_model_config
    from hexapod_vibration.paths import config_path

    n = 20_000
    accel = struts_from_z(G0 + tone(-31.0, 40.0, n))
    with Writer(tmp_path / "bag", version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as w:
        conns = [w.add_connection(t, STRUT_MSGTYPE, typestore=store()) for t in STRUT_TOPICS]
        for k in range(n):
            raw = strut_cdr(accel[k], k)
            for conn in conns:
                w.write(conn, k * 10**6, raw)
    model = load_model_config(config_path("pph_model.yaml"))
    tracemalloc.start()
    try:
        signals = load_signals(tmp_path / "bag", model)
        result = analyze_signals(signals, Request(tones=[40.0]))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert result.report["tones"][0]["uncontrolled_db"] == pytest.approx(-31.0, abs=0.2)
    assert all(len(s) == n for s in signals.series.values())
    assert peak < 10e6, f"{peak / 1e6:.1f} MB"


def test_the_following_table_lists_a_tone_that_moved_between_the_windows():
    """A spin-up: 30 Hz before control, held at 50 Hz at the end; a mismatch held at 40.4."""
    from hexapod_vibration.analysis.report_tables import format_following

    def row(f, before, after):
        return {"frequency_hz": f, "uncontrolled_db": -30.0, "controlled_db": -90.0,
                "reduction_db": 60.0, "frequency_span_hz": {"uncontrolled": before,
                                                            "controlled": after}}

    moved = format_following({"scenario": "s", "following_tones": [row(30.0, [30, 30],
                                                                       [50, 50])]})
    assert "30.00-30.00 -> 50.00-50.00" in moved
    assert format_following({"scenario": "s", "following_tones": [
        row(40.0, [40.4, 40.4], [40.4, 40.4])]}) == ""
