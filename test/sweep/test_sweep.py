"""The sweep tool: grids, Dask against serial, failures, resume, bad grids."""

import copy
import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from hexapod_vibration.core.sim import timeline
from hexapod_vibration.core.sim.scenario import Scenario, load_scenario
from hexapod_vibration.paths import scenario_path, share_directory
from hexapod_vibration.sweep import grid as grids
from hexapod_vibration.sweep import maps, results, runner

# A short Table 1 loop: identification 0.2 .. 3.4 s, 1 s windows (the controlled one 1 s
# after control-on), about 0.8 s of CPU.
TINY_SET = {
    "duration_s": 6.4, "identify_at_s": 0.2, "control_on_s": 4.4, "window_s": 1.0,
    "shaker.frequencies_hz": [40.0], "shaker.amplitudes_n": [80.0],
    "shaker.phases_rad": [0.0], "notch.tone_frequencies_hz": [40.0],
    "report_tones_hz": [40.0, 80.0],
    # the bare canceller of the paper: the 3.2 s tone identification (broadband takes 10 s),
    # no divergence guard and no anti-windup, so that a mu beyond the bound winds up
    "notch.settings": {"identification": "tones", "mu_policy": "manual",
                       "update_lowpass_hz": 0.0, "divergence_guard": False,
                       "weight_limit_n": 1000.0},
}
# Wall-clock and process fields: the only ones allowed to differ between two runs.
RUN_FIELDS = ("elapsed_s", "worker")


def write_grid(folder: Path, name: str = "tiny", **changes) -> Path:
    data = {"name": name, "base_scenario": "single_tone_harmonic", "set": dict(TINY_SET),
            "axes": {"notch.mu": {"values": [0.003, 0.05], "scale": "log"},
                     "notch.adaptation": ["decentralized", "centralized"]},
            "seeds": "common", "plot": {"x": "notch.adaptation", "y": "notch.mu"}}
    data.update(changes)
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def comparable(rows):
    return [{k: v for k, v in row.items() if k not in RUN_FIELDS} for row in rows]


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("serial")
    grid = grids.load_grid(write_grid(folder))
    summary = runner.run_sweep(grid, folder / "out", progress=False)
    return grid, folder / "out", summary


def test_serial_run_writes_a_row_per_point_with_the_report_metrics(serial_run):
    grid, out, summary = serial_run
    rows = results.read_table(out / results.TABLE_NAME)
    assert summary.computed == len(rows) == 4 and summary.failed == 0
    by = {(r["notch.adaptation"], r["notch.mu"]): r for r in rows}
    slow, fast = by[("decentralized", 0.003)], by[("decentralized", 0.05)]
    # mu = 0.003 is below the exact LTI bound (~0.011) and cancels the 40 Hz line;
    # 0.05 is below eq. 18's 0.25 but beyond the exact bound: the loop winds up.
    assert slow["attenuation_db"] > 40.0 and not slow["diverged"]
    assert fast["diverged"] and fast["peak_notch_command_n"] > 40.0
    # against the same run without control (same noise): a few dB below the bound (1 s
    # after control-on, the loop still settling), a limit cycle or worse beyond it
    assert slow["max_rise_vs_off_db"] < 6.0 and fast["max_rise_vs_off_db"] > 20.0
    # the loop's limit on the model (the paper's update: TINY_SET's notch settings replace
    # the base's, its update low-pass too) is far below the eq. 18 bound, and below 0.05
    assert slow["mu_bound_model"] < slow["mu_bound_identified"]
    assert slow["mu_bound_method"] == "eq. 18" and slow["mu_bound_model"] < 0.05
    assert slow["tones_hz"] == [40.0, 80.0] and slow["tones_controlled"] == [True, False]
    assert len(slow["band_centre_hz"]) == len(slow["band_controlled_db"]) > 10
    # both ran at the requested rate (guard off, below the identified bound)
    assert [slow["status"], fast["status"]] == ["ok", "ok"]
    assert slow["backed_off"] is False and slow["mu_limit_sensitivity"] is None
    assert summary.statuses == {"ok": 4}
    assert summary.figures and summary.figures[0].stat().st_size > 10_000


def test_two_dask_workers_give_the_serial_results(serial_run, tmp_path):
    grid, serial_out, _ = serial_run
    environ = dict(os.environ)
    client = runner.local_client(2)
    try:
        assert dict(os.environ) == environ      # Dask's worker settings stay in the workers
        assert len(client.scheduler_info()["workers"]) == 2
        assert set(client.run(lambda: os.environ.get("OMP_NUM_THREADS")).values()) == {"1"}
        summary = runner.run_sweep(grid, tmp_path / "dask", client, progress=False,
                                   plots=False)
    finally:
        runner.close_client(client)
    assert dict(os.environ) == environ
    assert summary.computed == 4
    dask_rows = results.read_table(tmp_path / "dask" / results.TABLE_NAME)
    serial_rows = results.read_table(serial_out / results.TABLE_NAME)
    assert comparable(dask_rows) == comparable(serial_rows)


def test_a_failing_point_is_recorded_and_the_others_run(tmp_path):
    # A 0.5 rad (29 deg) twist is beyond the pointing range: the core loop refuses it.
    path = write_grid(tmp_path, axes={"notch.mu": [0.003]},
                      points=[{"target_pose[5]": 0.0}, {"target_pose[5]": 0.5}], plot={})
    grid = grids.load_grid(path)
    summary = runner.run_sweep(grid, tmp_path / "out", progress=False, plots=False)
    rows = results.read_table(tmp_path / "out" / results.TABLE_NAME)
    assert summary.failed == 1 and [r["status"] for r in rows] == ["ok", "failed"]
    assert "ValueError" in rows[1]["error"] and "\n" not in rows[1]["error"]
    assert rows[1]["attenuation_db"] is None and rows[0]["attenuation_db"] > 30.0


def test_resume_skips_the_points_already_done(serial_run, tmp_path):
    grid, serial_out, _ = serial_run
    out = tmp_path / "out"
    for spec in grid.points[:3]:          # three points done by an interrupted sweep
        path = results.point_file(serial_out, spec.point_id)
        target = results.point_file(out, spec.point_id)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(path.read_text())
    ran = []
    summary = runner.run_sweep(grid, out, progress=False, plots=False,
                               on_point=lambda spec, row: ran.append(spec.point_id))
    assert ran == [grid.points[3].point_id]
    assert (summary.computed, summary.skipped) == (1, 3)
    again = runner.run_sweep(grid, out, progress=False, plots=False)
    assert again.computed == 0
    assert comparable(results.read_table(out / results.TABLE_NAME)) == comparable(
        results.read_table(serial_out / results.TABLE_NAME))


def test_a_changed_base_is_not_taken_as_done(tmp_path):
    first = grids.load_grid(write_grid(tmp_path))
    changed = grids.load_grid(write_grid(tmp_path, set={**TINY_SET, "duration_s": 6.5}))
    assert not {p.point_id for p in first.points} & {p.point_id for p in changed.points}


@pytest.mark.parametrize("change, message", [
    ({"axes": {"notch.mux": [0.1]}}, "no field 'mux' in notch"),
    ({"axes": {"shaker.frequencies_hz[3]": [40.0]}}, "index 3 out of range"),
    ({"axes": {"model_overrides.top_plate.mass": [10.0]}}, "no field 'mass'"),
    ({"axes": {"notch.mu": ["fast"]}}, "expected a number"),
    ({"axes": {"notch.mu": [-0.1]}}, "notch.mu must be >= 0"),
    ({"set": {"window_s": 0.0}}, "window_s"),
    ({"axes": {}}, "nothing to sweep"),
    ({"plot": {"x": "seed", "y": "notch.mu"}}, "plot.x"),
    ({"base_scenario": "no_such_scenario"}, "unknown scenario"),
    # the timeline against the identification the notch supervisor runs
    ({"set": {**TINY_SET, "notch.settings": {"identification": "broadband"}}},
     "control-on at 4.4 s falls inside the broadband identification (0.2-10.2 s); set "
     "control_on_s >= 11.2 s"),
    ({"set": {**TINY_SET, "window_s": 1.5}},
     "the uncontrolled window (2.9-4.4 s) overlaps the tones identification (0.2-3.4 s)"),
    ({"set": {**TINY_SET, "duration_s": 30.0, "control_on_s": 24.0, "window_s": 10.0},
      "points": [{"identify_at_s": 0.2}, {"identify_at_s": 12.0}]},
     "point 4 {identify_at_s: 12.0, notch.mu: 0.003, notch.adaptation: 'decentralized'}: "
     "the uncontrolled window (14-24 s) overlaps the tones identification (12-15.2 s)"),
])
def test_a_bad_grid_is_one_line_on_stderr_and_exit_2(tmp_path, change, message):
    path = write_grid(tmp_path, **change)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "hexapod_vibration.tools.sweep", str(path),
                           "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sweep: error:"), proc.stderr
    assert message in lines[0]
    assert not out.exists()


def test_the_identification_length_is_the_supervisors():
    """Longer tone segments make a longer identification; broadband is its own length."""
    base = load_scenario(scenario_path("single_tone_harmonic"))

    def interval(**settings):
        notch = dataclasses.replace(base.notch, tone_frequencies_hz=(40.0,),
                                    settings={"mu_policy": "manual", **settings})
        return timeline.identification_interval(dataclasses.replace(base, notch=notch),
                                                1000.0)

    tones, method = interval(identification="tones")
    assert method == "tones" and (tones.start_s, tones.stop_s) == (1.0, 4.2)
    slower, _ = interval(identification="tones", identification_measure_s=0.6)
    assert slower.stop_s == pytest.approx(1.0 + 8 * 0.7)        # (C + 2) segments
    broadband, method = interval(identification="broadband")
    assert method == "broadband" and broadband.stop_s - broadband.start_s == 10.0
    assert interval(identification="tones", auto_identify=False) is None


def test_not_yaml_is_one_line_exit_2(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: x\naxes: {notch.mu: [0.1\n", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "hexapod_vibration.tools.sweep", str(path),
                           "--out", str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1


def test_every_scenario_field_is_addressable_by_its_path():
    """New scenario fields need no code here: each leaf of the mapping resolves and sets."""
    base = dataclasses.asdict(load_scenario(scenario_path("single_tone_harmonic")))

    def leaves(node, prefix):
        if isinstance(node, dict) and node:
            for key, value in node.items():
                yield from leaves(value, f"{prefix}.{key}" if prefix else key)
        elif isinstance(node, (list, tuple)) and node:
            for k, value in enumerate(node):
                yield from leaves(value, f"{prefix}[{k}]")
        else:
            yield prefix, node

    paths = list(leaves(base, ""))
    assert {f.name for f in dataclasses.fields(Scenario)} <= {p.split(".")[0].split("[")[0]
                                                                for p, _ in paths}
    for path, value in paths:
        mapping = json.loads(json.dumps(base))
        value = json.loads(json.dumps(value))        # an empty tuple leaf is [] in JSON
        assert grids.get_path(mapping, path) == value
        grids.set_path(mapping, path, value)
        assert grids.get_path(mapping, path) == value
    # an element of a tuple (as dataclasses.asdict gives it) is set in the mapping itself
    mapping = copy.deepcopy(base)
    grids.set_path(mapping, "target_pose[5]", 0.25)
    grids.set_path(mapping, "shaker.frequencies_hz[1]", 81.0)
    assert mapping["target_pose"][5] == 0.25 and mapping["shaker"]["frequencies_hz"][1] == 81.0


def test_model_paths_and_seeds(tmp_path):
    grid = grids.load_grid(write_grid(
        tmp_path, axes={"model_overrides.top_plate.mass_kg": [10.0, 14.0],
                        "notch.mu": [0.002]}, seeds="per_point", plot={}))
    masses = [p.scenario["model_overrides"]["top_plate"]["mass_kg"] for p in grid.points]
    assert masses == [10.0, 14.0]
    seeds = [p.assignments["seed"] for p in grid.points]
    assert seeds[0] != seeds[1]
    assert seeds == [p.assignments["seed"] for p in grids.load_grid(grid.source).points]
    common = grids.load_grid(write_grid(tmp_path, name="c", axes={"notch.mu": [0.001, 0.002]},
                                        plot={}))
    assert {p.assignments["seed"] for p in common.points} == {1}


def test_shipped_grids_are_valid_and_installed():
    folder = share_directory() / "config" / "sweeps"
    names = {p.stem for p in folder.glob("*.yaml")}
    assert {"mu_bound", "noise", "payload"} <= names
    for name in names:
        grid = grids.load_grid(folder / f"{name}.yaml")
        assert grid.points and grid.plot["y"] == "notch.mu"
    setup = (share_directory() / "setup.py")
    if setup.is_file():
        assert "config/sweeps/*.yaml" in setup.read_text()


def test_a_point_that_did_not_run_as_asked_has_its_own_status(tmp_path):
    """Clamped, faded after backing off, refused, backed off with control kept."""
    refused = {"notch.settings": {"identification": "broadband"}, "duration_s": 13.4,
               "control_on_s": 11.4,
               "model_overrides.accelerometer.noise_density_g_per_sqrt_hz": 1e-3}
    guarded = {**TINY_SET["notch.settings"], "divergence_guard": True}
    path = write_grid(tmp_path, axes={}, plot={}, points=[
        {"notch.mu": 0.3},
        {"notch.mu": 0.2, "notch.settings": guarded},
        {"notch.mu": 0.003, **refused},
        {"notch.mu": 0.038, "duration_s": 8.4,         # the base's update low-pass and
         "notch.settings": {"identification": "tones", "mu_policy": "manual",
                            "divergence_guard": True,
                            "update_lowpass_hz": 10.0}}])     # anti-windup (40 N)
    summary = runner.run_sweep(grids.load_grid(path), tmp_path / "out", progress=False,
                               plots=False)
    clamped, faded, refused, backed_off = results.read_table(
        tmp_path / "out" / results.TABLE_NAME)
    assert summary.statuses == {"clamped": 1, "faded": 1, "refused": 1, "backed_off": 1}
    assert clamped["status"] == "clamped" and clamped["backed_off"] is False
    assert clamped["mu_in_force"] == pytest.approx(0.5 * clamped["mu_bound_identified"])
    assert f"mu 0.3 ran at {clamped['mu_in_force']:.4g}" in clamped["control_note"]
    # the guard lowered mu (0.2 / 4), still worse than off: faded out
    assert faded["status"] == "faded" and faded["backed_off"] is True
    assert faded["mu_in_force"] == pytest.approx(0.05)
    assert faded["control_note"].startswith("divergence guard:")
    assert refused["status"] == "refused" and refused["backed_off"] is False
    assert refused["control_note"].startswith("identification failed")
    assert refused["mu_bound_identified"] is None and refused["error"] is None
    # just above the loop's limit (0.033 on the model): lowered to 0.0095, control went on
    assert backed_off["status"] == "backed_off" and backed_off["backed_off"] is True
    assert backed_off["mu_in_force"] == pytest.approx(0.038 / 4)
    assert backed_off["attenuation_db"] > 40.0 and not backed_off["diverged"]
    assert "lower_mu" in backed_off["control_note"]
    assert "1 clamped, 1 backed_off, 1 faded, 1 refused" in summary.line()


def test_the_maps_show_values_only_where_control_ran():
    rows = [[{"status": "ok", "attenuation_db": 60.0},
             {"status": "clamped", "attenuation_db": 50.0},
             {"status": "backed_off", "attenuation_db": 40.0}],
            [{"status": "faded", "attenuation_db": 0.0},
             {"status": "refused", "attenuation_db": -1.0},
             {"status": "failed", "attenuation_db": None}]]
    values = maps._values(rows, "attenuation_db")
    assert values[0].tolist() == [60.0, 50.0, 40.0]
    assert np.isnan(values[1]).all()
