"""The printed tables of a report: the paper's layout, the following bands, the harmonics."""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod_vibration.analysis.control_outcome import ControlOutcome


def level_text(level: float | None, at_floor: bool | None) -> str:
    """A level (dB) as the tables print it: ``-115.1 (floor)`` when at the noise floor."""
    if level is None:
        return "-"
    return f"{level:.1f}" + (" (floor)" if at_floor else "")


def reduction_text(row: dict[str, Any]) -> str:
    """A reduction (dB), ``>= 84.1`` when it is a lower bound.

    A lower bound: the controlled level is at the noise floor and the uncontrolled one is
    not (a floor-to-floor difference bounds nothing).
    """
    if row["reduction_db"] is None:
        return "-"
    floor = row.get("at_noise_floor", {})
    bound = floor.get("controlled") and not floor.get("uncontrolled")
    return (">= " if bound else "") + f"{row['reduction_db']:.1f}"


def format_table(report: dict[str, Any], paper_reduction_db: dict[float, float] | None = None
                 ) -> str:
    """The paper's table layout: frequency, non-controlled, controlled, reduction (dB re 1 g).

    ``(floor)``: the level is the noise floor (the tone is below it); a reduction to the
    floor is a lower bound (``>=``).
    """
    header = (f"{'Frequency':>10} {'non-controlled':>17} {'controlled':>17} "
              f"{'reduction':>10}")
    if paper_reduction_db:
        header += f" {'paper reduction':>16}"
    lines = [f"{report['scenario']}  (20 log10(a_rms / 1 g), z-axis; * = notch tone)", header]
    headline = control_headline(report)
    if headline:
        lines.insert(0, headline)
    for row in report["tones"]:
        floor = row.get("at_noise_floor", {})
        mark = "*" if row["controlled"] else " "
        line = (f"{row['frequency_hz']:>8.1f}Hz{mark}"
                f"{level_text(row['uncontrolled_db'], floor.get('uncontrolled')):>17} "
                f"{level_text(row['controlled_db'], floor.get('controlled')):>17} "
                f"{reduction_text(row):>10}")
        if paper_reduction_db:
            paper = paper_reduction_db.get(row["frequency_hz"])
            line += f" {'-' if paper is None else f'{paper:.1f}':>16}"
        lines.append(line)
    conv = report["convergence_s"]
    loop = report["loop"]
    rate = loop["rate_hz"]
    lines.append(f"convergence {'-' if conv is None else f'{conv:.2f} s'}; loop {loop['mode']}, "
                 f"{loop['samples']} samples, {loop_missed_text(loop)}, "
                 f"{'-' if rate is None else f'{rate:.0f}'} samples/s")
    return "\n".join(lines)


def control_headline(report: dict[str, Any]) -> str:
    """The report's first line when control was not in force as asked ('' when it was)."""
    control = report.get("control")
    return ControlOutcome(**control).headline() if control else ""


def loop_missed_text(loop: dict[str, Any]) -> str:
    """``N missed``, with how many the notch never received, forecasts and stand-ins."""
    own, forecast = loop.get("notch_missed_samples"), loop.get("forecast_rows")
    notes = [f"{own} not received by the notch"] if own else []
    notes += [f"{forecast} late commands stood in for by forecasts"] if forecast else []
    stood_in = loop.get("stand_in_samples")
    notes += [f"{stood_in} samples with a force no controller computed"] if stood_in else []
    if loop.get("control_on_samples"):
        notes += [f"{loop['control_on_missed_samples']} late of the "
                  f"{loop['control_on_samples']} from sample "
                  f"{loop['control_on_counted_from']}, control on"]
    return f"{loop['missed_samples']} missed" + (f" ({'; '.join(notes)})" if notes else "")


def format_following(report: dict[str, Any]) -> str:
    """The following bands (``following_tones``) as a table; "" when no controlled tone moved.

    A tone whose track stayed at one frequency in both windows has its fixed-band row in
    the main table already; one that moved within a window or between them (a spin-up:
    30 Hz before control, 50 Hz at the end) is listed.
    """
    rows = report.get("following_tones") or []
    moved = [r for r in rows if np.ptp([edge for span in r["frequency_span_hz"].values()
                                        for edge in span]) > 1e-6]
    if not moved:
        return ""
    lines = [f"{report['scenario']}  (bands following the tones; tracks from the bag)",
             f"{'tone':>10} {'non-controlled':>17} {'controlled':>17} {'reduction':>10}"
             f"  {'track (Hz), uncontrolled -> controlled'}"]
    for row in moved:
        floor = row.get("at_noise_floor", {})
        spans = " -> ".join(f"{lo:.2f}-{hi:.2f}" for lo, hi in row["frequency_span_hz"].values())
        lines.append(f"{row['frequency_hz']:>8.1f}Hz"
                     f"{level_text(row['uncontrolled_db'], floor.get('uncontrolled')):>18} "
                     f"{level_text(row.get('controlled_db'), floor.get('controlled')):>17} "
                     f"{reduction_text(row):>10}  {spans}")
    return "\n".join(lines)


def format_harmonics(harmonics: dict[str, Any], scenario: str) -> str:
    """Fig. 4's numbers: each harmonic's level relative to the fundamental, and the THD."""
    lines = [f"{scenario}  (harmonics of {harmonics['frequencies_hz'][0]:g} Hz, z-axis)",
             f"{'Frequency':>10} {'level dB re 1 g':>16} {'re fundamental dB':>18}"]
    for f, lv, rel in zip(harmonics["frequencies_hz"], harmonics["levels_db"],
                          harmonics["relative_db"], strict=True):
        lines.append(f"{f:>8.0f}Hz {lv:>16.1f} {rel:>18.1f}")
    lines.append(f"THD {harmonics['thd_percent']:.1f} % over the {harmonics['harmonics']} "
                 f"harmonics below fs/2")
    return "\n".join(lines)
