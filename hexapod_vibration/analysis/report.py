"""From a rosbag2 bag of the contract topics to the paper's tables and figures.

No ROS import: bags are read with rosbags (:mod:`hexapod_vibration.analysis.bag_io`), so the
analysis runs on any machine. Every value sits on its loop sample (in-band index, or the
bag timestamps on the 1 kHz grid); missing samples are counted and never interpolated: a
spectrum window is the longest gap-free run inside it.

The level of a tone is ``20 log10(a_rms / 1 g)`` of its component in the top plate's z-axis
acceleration, recovered from the six accelerometers through the Stewart Jacobian, from a
10 s Blackman-Harris Welch spectrum. A tone below the local noise floor is reported at the
floor's level (flagged in ``details.json``), so a reduction is never larger than the floor
allows us to see.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexapod_vibration.analysis import bag_io
from hexapod_vibration.contract import DRIVER_STATUS, NOTCH_STATUS, SAMPLE_RATE_HZ, NotchState
from hexapod_vibration.core import spectrum
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.geometry import CubicHexapodGeometry
from hexapod_vibration.json_values import json_float, jsonable
from hexapod_vibration.json_values import write_json as write_json_values

FS = SAMPLE_RATE_HZ
DEFAULT_WINDOW_S = 10.0
ENVELOPE_WINDOW_S = 0.5
LOOP_KEYS = ("latency_ms_p50", "latency_ms_p99")


@dataclass
class BagSignals:
    """What the analysis needs from one bag, sample-indexed."""

    path: Path
    series: dict[str, bag_io.StrutSeries]
    driver_status: dict[str, str] = field(default_factory=dict)
    notch_statuses: list[dict[str, str]] = field(default_factory=list)
    weights_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 6, 2)))
    control_on_sample: int | None = None
    control_source: str = "none"

    @property
    def accel(self) -> bag_io.StrutSeries:
        """The /pph/accel series."""
        return self.series[bag_io.ACCEL_TOPIC]

    def notch_tones(self) -> list[float]:
        """Tones of the notch controller as it last reported them (Hz), or []."""
        for status in reversed(self.notch_statuses):
            if "tones_hz" in status:
                return [float(x) for x in json.loads(status["tones_hz"])]
        return []


def load_signals(bag_path: str | Path, control_on_s: float | None = None) -> BagSignals:
    """Read the bag; find when control went on (argument, notch diagnostics or parameters)."""
    series = bag_io.read_strut_topics(bag_path)
    signals = BagSignals(Path(bag_path), series)
    for _, name, values in bag_io.read_diagnostics(bag_path):
        if name == DRIVER_STATUS:
            signals.driver_status = values
        elif name == NOTCH_STATUS:
            signals.notch_statuses.append(values)
    signals.weights_index, signals.weights = bag_io.read_notch_weights(bag_path)
    _find_control_switch(signals, control_on_s)
    return signals


def _find_control_switch(signals: BagSignals, control_on_s: float | None) -> None:
    """Control-on sample: CLI value, else the notch's ``enabled_since_sample``, else none.

    ``/parameter_events`` carry only receive times; they are used (rounded to the sample
    grid of the accelerometer timestamps) only when the notch diagnostics are absent.
    """
    if control_on_s is not None:
        signals.control_on_sample, signals.control_source = int(round(control_on_s * FS)), "cli"
        return
    for status in signals.notch_statuses:
        since = int(status.get("enabled_since_sample", "-1"))
        if since >= 0 and status.get("state") in (NotchState.ADAPTING, NotchState.ENABLED):
            signals.control_on_sample, signals.control_source = since, "notch diagnostics"
            return
    events = [(t, v) for t, v in bag_io.read_parameter_events(signals.path) if v is True]
    accel = signals.accel
    if events and len(accel):
        nearest = np.searchsorted(accel.timestamp_ns, events[-1][0])
        nearest = min(int(nearest), len(accel) - 1)
        signals.control_on_sample = int(accel.sample_index[nearest])
        signals.control_source = "parameter event"


def z_acceleration(accel: bag_io.StrutSeries, geometry: CubicHexapodGeometry) -> np.ndarray:
    """Top-plate z-axis acceleration (m/s^2) per sample from the six accelerometers."""
    return geometry.platform_from_struts(accel.values)[:, 2]


def gap_free_window(index: np.ndarray, start: int, stop: int) -> tuple[slice, str]:
    """Rows of the longest run of consecutive samples with index in [start, stop)."""
    rows = np.flatnonzero((index >= start) & (index < stop))
    if rows.size == 0:
        return slice(0, 0), f"no samples in [{start}, {stop})"
    breaks = np.flatnonzero(np.diff(index[rows]) != 1)
    bounds = np.concatenate([[0], breaks + 1, [rows.size]])
    longest = int(np.argmax(np.diff(bounds)))
    a, b = rows[bounds[longest]], rows[bounds[longest + 1] - 1] + 1
    note = "" if b - a == stop - start else (
        f"window [{start}, {stop}) has {stop - start - rows.size} missing samples: used the "
        f"longest gap-free run of {b - a} samples")
    return slice(int(a), int(b)), note


def tone_levels(x: np.ndarray, tones: list[float]) -> tuple[list[float], list[float], list[bool]]:
    """(level dB re 1 g, floor dB re 1 g, at-floor flag) per tone; level >= floor."""
    raw, floor = spectrum.tone_and_floor_db(x, FS, tones)
    at_floor = [bool(r < fl) for r, fl in zip(raw, floor, strict=True)]
    level = [float(max(r, fl)) for r, fl in zip(raw, floor, strict=True)]
    return level, [float(fl) for fl in floor], at_floor


def settling_time_s(t_s: np.ndarray, level_db: np.ndarray, t_on_s: float,
                    final_window_s: float = 2.0, tolerance_db: float = 3.0) -> float:
    """Time from ``t_on_s`` until the level first comes within ``tolerance_db`` of its end.

    The end level is the mean power over the last ``final_window_s`` (in dB). First
    passage, not "stays within": a tone cancelled down to the noise floor has an envelope
    that fluctuates by more than 3 dB around the floor, which is not a lack of convergence.
    NaN if it never gets there.
    """
    final = t_s >= t_s[-1] - final_window_s
    final_db = 10.0 * np.log10(np.mean(10.0 ** (level_db[final] / 10.0)))
    inside = np.flatnonzero((level_db <= final_db + tolerance_db) & (t_s >= t_on_s))
    return float(t_s[inside[0]] - t_on_s) if inside.size else math.nan


def convergence_s(z: np.ndarray, on_row: int, tones: list[float]) -> float:
    """Seconds from control-on until every controlled tone is within 3 dB of its end level."""
    if not tones or on_row <= 0 or on_row >= z.size:
        return math.nan
    start = max(on_row - int(FS), 0)
    segment = z[start:]
    times = []
    for f in tones:
        t, env = spectrum.tone_envelope(segment, FS, f, window_s=ENVELOPE_WINDOW_S)
        with np.errstate(divide="ignore"):
            level = 20.0 * np.log10(np.maximum(env, 1e-15) / spectrum.G0)
        times.append(settling_time_s(t, level, (on_row - start) / FS))
    return float(max(times))


@dataclass
class Analysis:
    """Result of analysing one bag: the contract report, extra details and plot inputs."""

    report: dict[str, Any]
    details: dict[str, Any]
    z: np.ndarray
    windows: dict[str, slice]


def analyze_signals(signals: BagSignals, geometry: CubicHexapodGeometry,
                    tones: list[float] | None = None, scenario: str = "bag",
                    window_s: float = DEFAULT_WINDOW_S,
                    harmonics_of_hz: float = 0.0) -> Analysis:
    """Tone table, convergence and loop statistics of a bag (see module docstring)."""
    accel = signals.accel
    if len(accel) < 2:
        raise bag_io.BagError(f"{signals.path}: /pph/accel has {len(accel)} samples")
    z = z_acceleration(accel, geometry)
    controlled = signals.notch_tones()
    tones = list(tones) if tones else (controlled or _strongest_peaks(z))
    width = int(round(window_s * FS))
    index = accel.sample_index
    on = signals.control_on_sample
    notes: list[str] = []
    if on is None:
        windows = {"uncontrolled": gap_free_window(index, int(index[0]), int(index[-1]) + 1)}
    else:
        windows = {"uncontrolled": gap_free_window(index, on - width, on),
                   "controlled": gap_free_window(index, max(on, int(index[-1]) + 1 - width),
                                                 int(index[-1]) + 1)}
    levels = {}
    for name, (rows, note) in windows.items():
        if note:
            notes.append(f"{name}: {note}")
        levels[name] = tone_levels(z[rows], tones)
    rows_out = tone_rows(tones, controlled, levels)
    on_row = int(np.searchsorted(index, on)) if on is not None else -1
    report = {
        "scenario": scenario,
        "sample_rate_hz": FS,
        "tones": rows_out,
        "convergence_s": _json_float(convergence_s(z, on_row, [t["frequency_hz"] for t in rows_out
                                                                if t["controlled"]])),
        "loop": loop_statistics(signals),
    }
    details = _details(signals, levels, tones, notes, z, windows, harmonics_of_hz)
    return Analysis(report, details, z, {k: v[0] for k, v in windows.items()})


def tone_rows(tones: list[float], controlled: list[float], levels: dict) -> list[dict]:
    """report.json's ``tones`` rows from :func:`tone_levels` of each window (by name)."""
    rows = []
    for k, f in enumerate(tones):
        unc = levels["uncontrolled"][0][k]
        ctl = levels["controlled"][0][k] if "controlled" in levels else None
        rows.append({"frequency_hz": float(f),
                     "controlled": bool(any(abs(f - c) < 1e-6 for c in controlled)),
                     "uncontrolled_db": round(unc, 2),
                     "controlled_db": None if ctl is None else round(ctl, 2),
                     "reduction_db": None if ctl is None else round(unc - ctl, 2)})
    return rows


def _strongest_peaks(z: np.ndarray, count: int = 3) -> list[float]:
    """Frequencies (Hz, to 0.1 Hz) of the strongest spectral peaks above 5 Hz."""
    f, psd = spectrum.power_spectral_density(z - z.mean(), FS, segment_s=min(
        DEFAULT_WINDOW_S, z.size / FS))
    psd = np.where(f > 5.0, psd, 0.0)
    peaks = []
    for k in np.argsort(psd)[::-1]:
        if all(abs(f[k] - p) > 2.0 for p in peaks):
            peaks.append(float(round(f[k], 1)))
        if len(peaks) == count:
            break
    return sorted(peaks)


def loop_statistics(signals: BagSignals) -> dict[str, Any]:
    """The ``loop`` block: from the driver's diagnostics, else estimated from the bag."""
    accel, st = signals.accel, signals.driver_status
    missing = int(accel.missing_samples)
    if st:
        return {"mode": st.get("mode", "unknown"),
                "samples": int(st.get("samples", len(accel))),
                "missed_samples": int(st.get("missed_samples", 0)) + missing,
                "rate_hz": _json_float(float(st.get("rate_hz", "nan"))),
                **{k: _json_float(float(st.get(k, "nan"))) for k in LOOP_KEYS}}
    span_s = (accel.timestamp_ns[-1] - accel.timestamp_ns[0]) * 1e-9
    latency = _bag_latency_ms(signals)
    return {"mode": "unknown", "samples": len(accel) + missing, "missed_samples": missing,
            "rate_hz": _json_float((len(accel) - 1) / span_s if span_s > 0 else math.nan),
            "latency_ms_p50": _json_float(np.percentile(latency, 50) if latency.size else
                                          math.nan),
            "latency_ms_p99": _json_float(np.percentile(latency, 99) if latency.size else
                                          math.nan)}


def _bag_latency_ms(signals: BagSignals) -> np.ndarray:
    """Bag-timestamp delay from accel(n) to notch_command(n) (a recorder's view)."""
    cmd = signals.series.get("/pph/notch_command")
    if cmd is None or len(cmd) == 0:
        return np.zeros(0)
    common, ia, ic = np.intersect1d(signals.accel.sample_index, cmd.sample_index,
                                    return_indices=True)
    if common.size == 0:
        return np.zeros(0)
    return (cmd.timestamp_ns[ic] - signals.accel.timestamp_ns[ia]) * 1e-6


def _details(signals: BagSignals, levels: dict, tones: list[float], notes: list[str],
             z: np.ndarray, windows: dict, harmonics_of_hz: float) -> dict[str, Any]:
    details: dict[str, Any] = {
        "bag": str(signals.path),
        "control_on_sample": signals.control_on_sample,
        "control_on_source": signals.control_source,
        "levels_db_re_1g": {name: {"frequency_hz": tones, "level": lv, "noise_floor": fl,
                                   "at_noise_floor": af}
                            for name, (lv, fl, af) in levels.items()},
        "topics": {t: {"samples": len(s), "missing_samples": s.missing_samples,
                       "duplicate_samples": s.duplicate_samples,
                       "invalid_messages": s.invalid_messages, "index_source": s.index_source}
                   for t, s in signals.series.items()},
        "notes": notes,
        "driver_status": signals.driver_status,
        "notch_status": signals.notch_statuses[-1] if signals.notch_statuses else {},
    }
    if harmonics_of_hz > 0.0:
        rows = windows["uncontrolled"][0]
        details["harmonic_distortion"] = jsonable(
            spectrum.harmonic_distortion(z[rows], FS, harmonics_of_hz, n_harmonics=5),
            REPORT_DIGITS)
    return details


REPORT_DIGITS = 6
"""Decimals of the numbers in report.json and details.json."""


def _json_float(value: float) -> float | None:
    return json_float(value, REPORT_DIGITS)


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON (NaN written as null), numbers to 6 decimals."""
    write_json_values(path, data, REPORT_DIGITS)


def format_table(report: dict[str, Any], paper_reduction_db: dict[float, float] | None = None
                 ) -> str:
    """The paper's table layout: frequency, non-controlled, controlled, reduction (dB re 1 g)."""
    header = f"{'Frequency':>10} {'non-controlled':>15} {'controlled':>11} {'reduction':>10}"
    if paper_reduction_db:
        header += f" {'paper reduction':>16}"
    lines = [f"{report['scenario']}  (20 log10(a_rms / 1 g), z-axis; * = notch tone)", header]
    for row in report["tones"]:
        ctl = "-" if row["controlled_db"] is None else f"{row['controlled_db']:.1f}"
        red = "-" if row["reduction_db"] is None else f"{row['reduction_db']:.1f}"
        mark = "*" if row["controlled"] else " "
        line = (f"{row['frequency_hz']:>8.1f}Hz{mark}{row['uncontrolled_db']:>15.1f} "
                f"{ctl:>11} {red:>10}")
        if paper_reduction_db:
            paper = paper_reduction_db.get(row["frequency_hz"])
            line += f" {'-' if paper is None else f'{paper:.1f}':>16}"
        lines.append(line)
    conv = report["convergence_s"]
    loop = report["loop"]
    lines.append(f"convergence {'-' if conv is None else f'{conv:.2f} s'}; loop {loop['mode']}, "
                 f"{loop['samples']} samples, {loop['missed_samples']} missed, "
                 f"{loop['rate_hz'] or float('nan'):.0f} samples/s")
    return "\n".join(lines)


def analyze_bag(bag_path: str | Path, out_dir: str | Path, model: ModelConfig,
                tones: list[float] | None = None, scenario: str = "bag",
                window_s: float = DEFAULT_WINDOW_S, control_on_s: float | None = None,
                harmonics_of_hz: float = 0.0, plots: bool = True) -> Analysis:
    """Analyse a bag and write ``report.json``, ``details.json`` and the PNG plots.

    The bag is read and analysed completely before anything is written, so a bad bag
    leaves ``out_dir`` untouched.
    """
    signals = load_signals(bag_path, control_on_s)
    result = analyze_signals(signals, model.geometry, tones, scenario, window_s,
                             harmonics_of_hz)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "report.json", result.report)
    write_json(out / "details.json", result.details)
    if plots:
        from hexapod_vibration.analysis import plots as plotting
        result.details["plots"] = [p.name for p in plotting.write_all(out, signals, result,
                                                                      model)]
        write_json(out / "details.json", result.details)
    return result
