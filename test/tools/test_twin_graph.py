"""``experiment --twin`` through the ROS graph: the run, its twin, the comparison (lockstep).

One short run (6.3 s, control on at 4.3 s, 2 s windows; the uncontrolled window is the
0.5 s between the identification's ring-down and control-on) and its twin: the twin check passes
only if the graph is deterministic up to control-on (the z acceleration identical to
1e-9 m/s^2 on every sample before it), and the comparison is in report.json. The nodes
composed in one process (``pph_graph``): half the CPU of three processes.
"""

from __future__ import annotations

import json

import yaml
from node_graph import run_experiment
from test_experiment import SCENARIO as SHORT_RUN

SCENARIO = {**SHORT_RUN, "name": "short_twin", "identify_at_s": 0.1, "duration_s": 6.3,
            "control_on_s": 4.3, "description": "a short Table 1 run and its twin"}


def test_experiment_twin_runs_the_twin_and_compares_the_same_samples(ros_env, tmp_path):
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump(SCENARIO))
    out = tmp_path / "run"
    result = run_experiment(ros_env, path, out, "--twin", "--composed", "--no-plots",
                            timeout=400)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "against its twin" in result.stdout
    twin_report = json.loads((out / "twin" / "report.json").read_text())
    assert twin_report["tones"][0]["controlled_db"] is None        # control never went on
    section = json.loads((out / "report.json").read_text())["twin"]
    assert section["control_on_sample"] == 4300
    assert section["window"] == {"first_sample": 4300, "samples": 2000}
    rows = {r["frequency_hz"]: r for r in section["tones"]}
    assert rows[40.0]["controlled"] and rows[40.0]["reduction_db"] > 20.0
    assert abs(rows[80.0]["reduction_db"]) < 6.0
    assert section["bands"]["largest_rise_db"] is not None
