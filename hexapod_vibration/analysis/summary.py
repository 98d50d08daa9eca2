"""``summary.md``: the demo's tables in Markdown, as the README shows them.

One function turns an :class:`~hexapod_vibration.analysis.report.Analysis` into the
README's table layout (levels in dB re 1 g, ``(floor)`` when a level is the noise floor,
``>=`` when a reduction is a lower bound because the controlled level is at the floor),
so the README's tables are copied from a fresh ``make demo`` rather than typed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from hexapod_vibration.analysis.report_tables import (
    control_headline,
    level_text,
    loop_missed_text,
    reduction_text,
)


def tone_table(result: Any) -> list[str]:
    """Markdown rows of a scenario's tone table (with the paper's column if known)."""
    paper = result.paper_reduction_db
    head = "| frequency | uncontrolled | controlled | reduction |"
    rule = "|---|---|---|---|"
    if paper:
        head, rule = head + " paper reduction |", rule + "---|"
    lines = [head, rule]
    for row in result.report["tones"]:
        floor = row.get("at_noise_floor", {})
        cells = [f"{row['frequency_hz']:g} Hz{' *' if row['controlled'] else ''}",
                 level_text(row["uncontrolled_db"], floor.get("uncontrolled")),
                 level_text(row["controlled_db"], floor.get("controlled")),
                 reduction_text(row)]
        if paper:
            value = paper.get(row["frequency_hz"])
            cells.append("-" if value is None else f"{value:.1f}")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def harmonics_table(harmonics: dict[str, Any]) -> list[str]:
    """Markdown rows of Fig. 4's harmonics (level, and relative to the fundamental)."""
    lines = ["| harmonic | frequency | level (dB re 1 g) | re fundamental (dB) |",
             "|---|---|---|---|"]
    for k, (f, lv, rel) in enumerate(zip(harmonics["frequencies_hz"], harmonics["levels_db"],
                                         harmonics["relative_db"], strict=True), start=1):
        lines.append(f"| {k} | {f:g} Hz | {lv:.1f} | {rel:.1f} |")
    return lines


def scenario_section(result: Any, out_dir: Path) -> list[str]:
    """A scenario's heading, table, convergence/THD line and figures."""
    report, details = result.report, result.details
    lines = [f"## {report['scenario']}", ""]
    headline = control_headline(report)
    if headline:
        lines += [f"**{headline}**", ""]
    record = details.get("run_record") or {}
    if result.harmonics is not None and not any(r["controlled"] for r in report["tones"]):
        hd = result.harmonics
        lines += harmonics_table(hd)
        lines += ["", f"THD {hd['thd_percent']:.1f} % over the {hd['harmonics']} harmonics "
                      "below fs/2."]
    else:
        lines += tone_table(result)
        conv = report["convergence_s"]
        per_tone = ", ".join(f"{f} Hz {v['convergence_s']:.2f} s"
                             for f, v in details.get("convergence", {}).items()
                             if conv is not None and v["convergence_s"] is not None and any(
                                 r["controlled"] and f"{r['frequency_hz']:g}" == f
                                 for r in report["tones"]))
        lines += ["", f"Convergence (control-on to within 3 dB of the final level) "
                      f"{'-' if conv is None else f'{conv:.2f} s'}"
                      + (f" ({per_tone})." if per_tone else ".")]
    loop = report["loop"]
    windows = ", ".join(f"{name} from sample {w['first_sample']} ({w['samples'] / 1000:g} s)"
                        for name, w in details.get("windows", {}).items())
    lines += ["", f"Loop: {loop['mode']}, {loop['samples']} samples, "
                  f"{loop_missed_text(loop)}. Windows: {windows}. "
                  f"Window length asked: {record.get('window_s', '-')} s."]
    notes = details.get("notes", [])
    if notes:
        lines += ["", *[f"- note: {n}" for n in notes]]
    folder = Path(details["bag"]).parent
    figures = [name for name in details.get("plots", []) if name.endswith(".png")]
    if figures:
        rel = os.path.relpath(folder, out_dir)
        lines += ["", "Figures: " + ", ".join(f"[{n}]({rel}/{n})" for n in figures)]
    return [*lines, ""]


def write_summary(path: Path, results: list[Any], out_dir: Path) -> Path:
    """Write ``summary.md`` with every scenario's section; return its path."""
    lines = ["# Demo summary", "",
             "Levels in dB re 1 g of the top plate's z acceleration; `*` = notch tone; "
             "`(floor)`: the level is the local noise floor (the tone is below it); "
             "`>=`: the reduction is a lower bound (controlled level at the floor).", ""]
    for result in results:
        lines += scenario_section(result, out_dir)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text("\n".join(lines), encoding="utf-8")
    tmp.replace(path)
    return path
