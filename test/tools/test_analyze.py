"""``analyze`` on bags written independently with rosbags' own Writer."""

import json
import shutil

import numpy as np
import pytest

from hexapod_vibration.analysis.bag_writer import write_strut_bag
from hexapod_vibration.core.model.geometry import CubicHexapodGeometry
from hexapod_vibration.core.spectrum import G0
from hexapod_vibration.tools import analyze

FS = 1000.0
GEO = CubicHexapodGeometry()
TONES = {40.0: -30.0, 80.0: -50.0, 120.0: -60.0}     # dB re 1 g, z axis
ON_S, DURATION_S = 12.0, 24.0


def _z_amplitude(level_db):
    return np.sqrt(2.0) * G0 * 10 ** (level_db / 20.0)


def synthetic_accel(n_samples, controlled_drop_db=0.0, on_sample=None, seed=0):
    """Six strut accelerations whose platform z component carries the known tones."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) / FS
    z = np.zeros(n_samples)
    for k, (f, level) in enumerate(TONES.items()):
        amp = np.full(n_samples, _z_amplitude(level))
        if on_sample is not None and f == 40.0:
            amp[on_sample:] *= 10 ** (-controlled_drop_db / 20.0)
        z += amp * np.sin(2 * np.pi * f * t + k)
    platform = np.zeros((n_samples, 6))
    platform[:, 2] = z + G0
    platform += rng.normal(0, 1e-5, platform.shape)
    return platform @ GEO.top_jacobian.T


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_known_tones_are_measured_within_half_a_db(tmp_path, storage):
    n = int(DURATION_S * FS)
    on = int(ON_S * FS)
    accel = synthetic_accel(n, controlled_drop_db=40.0, on_sample=on)
    bag = write_strut_bag(tmp_path / "bag", {"/pph/accel": (np.arange(n), accel)},
                          storage=storage)
    out = tmp_path / "out"
    code = analyze.main([str(bag), "--out", str(out), "--tones", "40", "80", "120",
                         "--control-on", str(ON_S), "--no-plots"])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert set(report) == {"scenario", "sample_rate_hz", "tones", "convergence_s", "loop",
                           "control"}
    assert report["control"]["outcome"] == "unknown"          # no notch status in the bag
    assert report["sample_rate_hz"] == 1000.0
    rows = {row["frequency_hz"]: row for row in report["tones"]}
    for f, level in TONES.items():
        assert rows[f]["uncontrolled_db"] == pytest.approx(level, abs=0.5)
    assert rows[40.0]["controlled_db"] == pytest.approx(TONES[40.0] - 40.0, abs=0.5)
    assert rows[40.0]["reduction_db"] == pytest.approx(40.0, abs=0.7)
    assert rows[80.0]["reduction_db"] == pytest.approx(0.0, abs=0.5)
    assert report["loop"]["missed_samples"] == 0
    assert report["loop"]["samples"] == n


def test_bag_without_control_switch_is_one_uncontrolled_window(tmp_path):
    n = 12000
    bag = write_strut_bag(tmp_path / "bag", {"/pph/accel": (np.arange(n), synthetic_accel(n))},
                          in_band_index=False)
    out = tmp_path / "out"
    assert analyze.main([str(bag), "--out", str(out), "--tones", "40", "80"]) == 0
    report = json.loads((out / "report.json").read_text())
    for row in report["tones"]:
        assert row["controlled_db"] is None and row["reduction_db"] is None
        assert row["uncontrolled_db"] == pytest.approx(TONES[row["frequency_hz"]], abs=0.5)
    assert report["convergence_s"] is None
    assert (out / "spectra.png").stat().st_size > 10_000


def test_missing_samples_are_reported_not_interpolated(tmp_path):
    n = 24000
    index = np.delete(np.arange(n), np.arange(5000, 5040))
    accel = synthetic_accel(n)[index]
    bag = write_strut_bag(tmp_path / "bag", {"/pph/accel": (index, accel)})
    out = tmp_path / "out"
    assert analyze.main([str(bag), "--out", str(out), "--tones", "40", "--no-plots"]) == 0
    report = json.loads((out / "report.json").read_text())
    details = json.loads((out / "details.json").read_text())
    assert report["loop"]["missed_samples"] == 40
    assert details["topics"]["/pph/accel"]["missing_samples"] == 40
    assert any("missing samples" in note for note in details["notes"])


def test_truncated_bag_gives_a_clear_error_and_writes_nothing(tmp_path, capsys):
    n = 5000
    bag = write_strut_bag(tmp_path / "bag", {"/pph/accel": (np.arange(n), synthetic_accel(n))},
                          storage="mcap")
    data = next(bag.glob("*.mcap"))
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    out = tmp_path / "out"
    assert analyze.main([str(bag), "--out", str(out)]) == 2
    assert "analyze:" in capsys.readouterr().err
    assert not out.exists()


def test_not_a_bag_and_bad_arguments_are_rejected(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert analyze.main([str(empty), "--out", str(tmp_path / "o")]) == 2
    assert "analyze:" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        analyze.main([str(empty), "--out", str(tmp_path / "o"), "--tones", "600"])


def test_bag_without_accel_lists_its_topics(tmp_path, capsys):
    n = 100
    bag = write_strut_bag(tmp_path / "bag", {"/pph/eddy": (np.arange(n), np.zeros((n, 6)))})
    assert analyze.main([str(bag), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "/pph/accel" in err and "/pph/eddy" in err
    shutil.rmtree(tmp_path / "o", ignore_errors=True)
