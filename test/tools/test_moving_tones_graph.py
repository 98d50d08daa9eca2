"""Moving tones through the ROS graph (lockstep): frequency tracking and the tachometer.

The nodes composed in one process (``pph_graph``, the same nodes and topics at half the
CPU of three processes; the layouts' equality is tested in ``test_experiment``).

Short runs of the experiment runner: the driver's rotor and frequency topics, the notch
node's reference input and estimates, the recorder and the report's following bands, end
to end. They need the notch supervisor's tracking API (``tone_estimates_hz``,
``set_reference_frequency``): skipped where it does not exist yet.

The settings are the ``mismatch`` scenario's (its broadband identification; the
tachometer run too: tones that follow a reference need it), on a shorter timeline:
identification from 0.5 s (10 s), 2 s windows, 4.5 s of control at mu 0.002
(``mu_policy: manual``: these runs check the graph, not the policy's rate). Missed
samples are not asserted here: a lockstep timeout depends on the machine's load.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from node_graph import run_experiment

from hexapod_vibration.analysis.bag_reading import read_bag
from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor
from hexapod_vibration.paths import scenario_path

pytestmark = pytest.mark.skipif(
    not hasattr(NotchSupervisor, "tone_estimates_hz")
    or not hasattr(NotchSupervisor, "set_reference_frequency"),
    reason="needs the notch supervisor's frequency tracking (branch tracking)")

IDENTIFY_AT_S, WINDOW_S, CONTROL_S = 0.5, 2.0, 4.5
BROADBAND_S = 10.0
"""Identification time (s): the broadband 10 s record."""


def _short(changes: dict, notch: dict) -> dict:
    """The mismatch scenario's timeline, shortened, with ``changes`` on top.

    ``notch`` is added to the scenario's own notch settings (its broadband identification), with
    ``mu_policy: manual``: these runs check the graph, not the policy's rate (the mismatch
    scenario's auto policy bounds 45/91 Hz to a slower rate than 5 s of control need).
    Control goes on a window after the identification.
    """
    base = yaml.safe_load(scenario_path("mismatch").read_text())
    control_on_s = IDENTIFY_AT_S + BROADBAND_S + WINDOW_S
    base.update(identify_at_s=IDENTIFY_AT_S, window_s=WINDOW_S, control_on_s=control_on_s,
                duration_s=control_on_s + CONTROL_S)
    notch = {"mu_policy": "manual", **notch}
    base.update(changes)
    base["notch"] = {**base["notch"], **notch}
    return base


def _run(ros_env, tmp_path, scenario: dict, plots: bool = True) -> dict:
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(scenario))
    out = tmp_path / "run"
    result = run_experiment(ros_env, path, out, "--composed",
                            *(() if plots else ("--no-plots",)), timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    if plots:
        assert (out / "frequencies.png").stat().st_size > 10_000
    else:
        assert not list(out.glob("*.png")) and not (out / "spectra.csv").exists()
    return {"report": report, "bag": read_bag(out / "bag", {}), "out": out}


def test_tracking_follows_a_1_percent_mismatch_through_the_graph(ros_env, tmp_path):
    run = _run(ros_env, tmp_path, _short(
        {"name": "mismatch_tracking_short", "report_tones_hz": [40.4]},
        {"tone_frequencies_hz": [40.0], "frequency_tracking": True, "tracking_range_hz": 2.0}))
    index, estimates = run["bag"].frequencies["/pph/notch_frequencies"]
    _, truth = run["bag"].frequencies["/pph/disturbance_frequencies"]
    assert truth[-1] == pytest.approx([40.4])
    assert abs(estimates[-1, 0] - 40.4) < 0.05         # the estimate found the tone
    row, = run["report"]["following_tones"]
    assert row["source"] == "/pph/disturbance_frequencies"
    assert row["reduction_db"] >= 30.0


def test_the_tachometer_drives_the_tones_through_the_graph(ros_env, tmp_path):
    """A rotor at 45.5 Hz (orders 1 and 2); the notch told 45 and 91 Hz follows 1x and 2x."""
    run = _run(ros_env, tmp_path, _short(
        {"name": "tachometer_short",
         "shaker": {"frequencies_hz": [40.0], "amplitudes_n": [0.0], "noise_rms_n": 0.5},
         "rotor": {"orders": [1.0, 2.0], "amplitudes_n": [60.0, 60.0],
                   "reference_speed_hz": 45.5, "profile_time_s": [0.0],
                   "profile_speed_hz": [45.5], "tachometer": True},
         "report_tones_hz": [45.5, 91.0]},
        # tones that follow a reference need the broadband identification's G(f)
        {"tone_frequencies_hz": [45.0, 91.0], "reference_harmonics": [1.0, 2.0]}),
        plots=False)
    bag = run["bag"]
    ref_index, reference = bag.frequencies["/pph/reference_frequency"]
    samples = run["report"]["loop"]["samples"]
    assert np.array_equal(ref_index, np.arange(samples))        # one reading per sample
    assert np.all(reference[:, 0] == 45.5)
    _, estimates = bag.frequencies["/pph/notch_frequencies"]
    assert estimates[-1] == pytest.approx([45.5, 91.0], abs=1e-9)
    rows = {r["frequency_hz"]: r for r in run["report"]["following_tones"]}
    assert set(rows) == {45.0, 91.0}
    for row in rows.values():
        assert row["source"] == "/pph/disturbance_frequencies"
        assert row["reduction_db"] >= 40.0
