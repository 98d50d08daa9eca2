"""One bag (and its uncontrolled twin) analysed, and every output written.

Above the report, the twin comparison and the figures: ``analyze`` and ``experiment`` call
:func:`analyze_bag`.
"""

from __future__ import annotations

from pathlib import Path

from hexapod_vibration.analysis import twin
from hexapod_vibration.analysis.bag_signals import load_signals
from hexapod_vibration.analysis.plots import write_all as write_figures
from hexapod_vibration.analysis.report import Analysis, Request, analyze_signals
from hexapod_vibration.analysis.report_json import write_json
from hexapod_vibration.core.model.config import ModelConfig


def analyze_bag(bag_path: str | Path, out_dir: str | Path, model: ModelConfig,
                request: Request | None = None, control_on_s: float | None = None,
                plots: bool = True, twin_bag: str | Path | None = None,
                twin_segment_s: float | None = None) -> Analysis:
    """Analyse a bag and write ``report.json``, ``details.json``, the PNG and CSV figures.

    ``twin_bag``: the same run with control never on; the report gets a ``twin`` section
    (:mod:`hexapod_vibration.analysis.twin`, ``twin_segment_s`` its over-time window).
    The bags are read and analysed completely before anything is written, so a bad bag
    (or a twin that is not this run's) leaves ``out_dir`` untouched.
    """
    signals = load_signals(bag_path, model, control_on_s)
    twin_signals = None if twin_bag is None else load_signals(twin_bag, model)
    result = analyze_signals(signals, request or Request())
    if twin_signals is not None:
        result.report["twin"] = twin.compare(signals, twin_signals, result,
                                             twin_segment_s or twin.DEFAULT_SEGMENT_S)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "report.json", result.report)
    if plots:
        result.details["plots"] = [p.name for p in write_figures(out, signals, result)]
    write_json(out / "details.json", result.details)
    return result
