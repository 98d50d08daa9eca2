"""What a user sees: the progress line, the demo's summary, the figures and CSV (no ROS)."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
from bag_factory import notch_status, struts_from_z, tone, write_bag
from PIL import Image

from hexapod_vibration.analysis.bag_analysis import analyze_bag
from hexapod_vibration.analysis.report import Request
from hexapod_vibration.analysis.run_record import RunRecord
from hexapod_vibration.analysis.summary import write_summary
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.spectrum import G0
from hexapod_vibration.paths import config_path
from hexapod_vibration.tools import experiment
from hexapod_vibration.tools.progress import Progress

MODEL = load_model_config(config_path("pph_model.yaml"))
ON, END = 16000, 34000


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_one_updating_line_with_an_eta_on_a_terminal():
    stream = Terminal()
    progress = Progress("close_tones", 36.0, stream)
    progress._start = (0.0, 0.0)
    text = progress.line(9.0, "539.7712", "adapting", "running", now=18.0)
    assert "( 25 %)" in text and "ETA 0:54" in text       # 27 sim s left at 0.5 sim s/s
    assert "540 samples/s" in text and "539.77" not in text
    for k in range(3):
        progress._last = -1e9
        progress.update(float(k), "540", "adapting", "running")
    out = stream.getvalue()
    assert out.count("\r") == 3 and "\n" not in out
    progress.clear()
    assert stream.getvalue().endswith("\r\x1b[K")


def test_progress_is_plain_lines_when_not_a_terminal():
    stream = io.StringIO()
    progress = Progress("close_tones", 36.0, stream)
    for k in range(2):
        progress._last = -1e9
        progress.update(float(k), None, "-", "waiting")
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2 and "\r" not in stream.getvalue()
    assert all("ETA" in line and "- samples/s" in line for line in lines)


def _table1_bag(tmp_path):
    z = G0 + tone(-31.0, 40.0, END) + tone(-68.0, 80.0, END, 0.4) + tone(-66.0, 120.0, END)
    n = np.arange(END)
    z[ON:] -= (1 - np.exp(-(n[ON:] - ON) / 500.0)) * (tone(-31.0, 40.0, END)[ON:])
    statuses = [(s, notch_status(s, "adapting" if s >= ON else "disabled", [40.0, 80.0],
                                 ON if s >= ON else -1, (1000, 4199)))
                for s in range(0, END, 1000)]
    record = RunRecord("single_tone_harmonic", [40.0, 80.0, 120.0], [40.0, 80.0], 10.0, END,
                       ON, 1000, 3200, paper_reduction_db={"40": 66.4, "80": 40.2,
                                                           "120": -10.0})
    return write_bag(tmp_path / "bag", struts_from_z(z), statuses=statuses,
                     run_record=record.to_json())


def _fig4_bag(tmp_path):
    n = 12000
    harmonics = {40.0: -2.2, 80.0: -22.9, 280.0: -20.3, 480.0: -27.8}
    z = G0 + sum(tone(level, f, n, 0.1 * f) for f, level in harmonics.items())
    record = RunRecord("plant_response", [40.0, 80.0, 120.0], [], 10.0, n,
                       harmonics_of_hz=40.0)
    return write_bag(tmp_path / "fig4", struts_from_z(z), run_record=record.to_json())


def test_demo_runs_figure_4_and_writes_a_summary_of_the_three_tables(tmp_path):
    assert experiment.DEMO_SCENARIOS == ("single_tone_harmonic", "close_tones",
                                         "plant_response")
    table1 = analyze_bag(_table1_bag(tmp_path), tmp_path / "t1", MODEL)
    fig4 = analyze_bag(_fig4_bag(tmp_path), tmp_path / "f4", MODEL)
    summary = write_summary(tmp_path / "summary.md", [table1, fig4], tmp_path).read_text()
    assert "## single_tone_harmonic" in summary and "## plant_response" in summary
    assert "| 40 Hz * | -31.0 |" in summary and "| 66.4 |" in summary
    assert "THD" in summary and "11 harmonics below fs/2" in summary
    expected = np.sqrt(sum(10 ** ((lv + 2.2) / 10) for lv in (-22.9, -20.3, -27.8)))
    assert f"THD {100 * expected:.1f} %" in summary
    assert experiment.scenario_table(fig4).splitlines()[-1].startswith("THD")
    assert "paper reduction" in experiment.scenario_table(table1)


def test_figures_are_150_dpi_and_the_spectra_are_also_csv(tmp_path):
    out = tmp_path / "out"
    result = analyze_bag(_table1_bag(tmp_path), out, MODEL, Request())
    details = json.loads((out / "details.json").read_text())
    pngs = [name for name in details["plots"] if name.endswith(".png")]
    assert {"spectra.png", "convergence.png"} <= set(pngs)
    for name in pngs:
        with Image.open(out / name) as image:
            assert min(image.info["dpi"]) >= 149.9, name
            assert image.size[0] >= 1100, name
    with (out / "spectra.csv").open() as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ["frequency_hz", "uncontrolled_psd_db_re_1g2_per_hz",
                       "controlled_psd_db_re_1g2_per_hz"]
    freq = np.array([float(r[0]) for r in rows[1:]])
    psd = np.array([float(r[1]) for r in rows[1:]])
    assert freq[int(np.argmax(np.where(freq > 5, psd, -1e9)))] == 40.0
    assert result.report["tones"][0]["uncontrolled_db"] < psd.max()


def test_experiment_exits_non_zero_when_the_control_asked_for_never_engaged(capsys):
    from types import SimpleNamespace

    from hexapod_vibration.tools.experiment import _control_exit_code

    def result(outcome: str, reason: str = "") -> SimpleNamespace:
        return SimpleNamespace(report={"scenario": f"s_{outcome}", "control": {
            "outcome": outcome, "reason": reason}})

    assert _control_exit_code([result("controlled"), result("faded", "guard")]) == 0
    assert _control_exit_code([result("controlled"), result("refused", "bound 0")]) == 1
    assert "s_refused: control never engaged (refused: bound 0)" in capsys.readouterr().err
    assert _control_exit_code([result("never_engaged")]) == 1
