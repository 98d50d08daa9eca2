"""From a bag's signals to the report: the paper's tone table, convergence, loop, details.

No ROS import. The bag is read in one streaming pass
(:func:`~hexapod_vibration.analysis.bag_signals.load_signals`); every value sits on its loop
sample, samples are counted from the run's sample 0, missing ones are never interpolated.
Each tone's level (:mod:`hexapod_vibration.analysis.levels`, at the noise floor at worst)
is measured in the uncontrolled and the controlled window
(:mod:`hexapod_vibration.analysis.report_windows`: the notch's identification left out),
in a band following the tone when it moved (:mod:`hexapod_vibration.analysis.following`),
and the recorded sensitivity prediction is compared with the measured one
(:mod:`hexapod_vibration.analysis.sensitivity_check`).

What an experiment recorded about its run
(:class:`~hexapod_vibration.analysis.run_record.RunRecord`, in the bag's ``metadata.yaml``
``custom_data``) sets the scenario name, tones, windows and the paper's column, so
``analyze BAG`` gives exactly the experiment's report.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from hexapod_vibration.analysis.bag_files import BagError
from hexapod_vibration.analysis.bag_signals import FS, BagSignals
from hexapod_vibration.analysis.control_outcome import ControlOutcome, control_outcome
from hexapod_vibration.analysis.following import configured_tones, following_tones, snap_to_tones
from hexapod_vibration.analysis.late_commands import late_since
from hexapod_vibration.analysis.levels import convergence_s, levels_over_time, tone_levels
from hexapod_vibration.analysis.report_json import report_float, report_jsonable
from hexapod_vibration.analysis.report_windows import (
    DEFAULT_WINDOW_S,
    IDENTIFICATION_SETTLE_S,
    WindowTooShort,
    identification_intervals,
    report_windows,
    required_window_s,
)
from hexapod_vibration.analysis.sensitivity_check import (
    oscillators_moved_hz,
    sensitivity_comparison,
)
from hexapod_vibration.core import spectrum

LOOP_KEYS = ("latency_ms_p50", "latency_ms_p99")


@dataclass
class Analysis:
    """Result of analysing one bag: the contract report, extra details and plot inputs."""

    report: dict[str, Any]
    details: dict[str, Any]
    z: np.ndarray
    windows: dict[str, slice]
    index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    levels_over_time: dict[float, dict[str, Any]] = field(default_factory=dict)
    identification: list[tuple[int, int]] = field(default_factory=list)
    paper_reduction_db: dict[float, float] = field(default_factory=dict)
    harmonics: dict[str, Any] | None = None
    sensitivity_curves: dict[str, np.ndarray] = field(default_factory=dict)
    """Predicted (``frequency_hz``, ``predicted_db``) and measured (``measured_frequency_hz``,
    ``measured_db``) |S| for ``sensitivity.png``; empty without a recorded prediction.
    A twin comparison adds the H1 estimate (``twin_frequency_hz``, ``twin_db``)."""
    controlled_hz: list[float] = field(default_factory=list)
    """The notch's tones (Hz) as the report uses them (snapped to the report tones)."""
    tracked_hz: list[float] = field(default_factory=list)
    """The notch's configured tones (Hz) whose tracks give ``following_tones``."""


@dataclass(frozen=True)
class Request:
    """What to report; None fields come from the run record, else from the bag."""

    tones: list[float] | None = None
    scenario: str | None = None
    window_s: float | None = None
    harmonics_of_hz: float | None = None


def analyze_signals(signals: BagSignals, request: Request = Request()) -> Analysis:
    """Tone table, convergence and loop statistics of a bag (see module docstring).

    Raises:
        WindowTooShort: a window's usable run is shorter than the tones need.
        BagError: too few accelerometer samples.
    """
    accel, rec = signals.accel, signals.record
    if len(accel) < 2:
        raise BagError(f"{signals.path}: /pph/accel has {len(accel)} samples")
    z, index = signals.z, accel.sample_index
    controlled = signals.notch_tones() or (rec.notch_tones_hz if rec else [])
    tones = [float(f) for f in (request.tones or (rec.report_tones_hz if rec else None)
                                or controlled or _strongest_peaks(z))]
    configured = configured_tones(signals, controlled)
    controlled = snap_to_tones(controlled, tones)
    window_s = request.window_s or (rec.window_s if rec else None)
    ident, ident_source = identification_intervals(signals)
    margin = int(round(IDENTIFICATION_SETTLE_S * FS))
    excluded = [(a, b + margin) for a, b in ident]
    notes = [f"recovered: {signals.recovered}"] if signals.recovered else []
    windows = report_windows(signals, index, window_s, excluded, notes)
    need_s = required_window_s(tones)
    levels = {}
    for name, rows in windows.items():
        length_s = (rows.stop - rows.start) / FS
        if length_s < need_s:
            raise WindowTooShort(
                f"{signals.path}: the {name} window's usable run is {length_s:.3f} s; the "
                f"spectrum needs {need_s:.3g} s to separate {_fmt_tones(tones)} (notes: "
                f"{'; '.join(notes) or 'none'})")
        segment = min(spectrum.DEFAULT_SEGMENT_S, length_s)
        levels[name] = tone_levels(z[rows], tones, segment)
    rows_out = tone_rows(tones, controlled, levels)
    on = signals.control_on_sample
    over_time = levels_over_time(z, index, on, tones, controlled)
    window = windows.get("controlled")
    outcome = control_outcome(signals.notch_statuses, on,
                              int(index[window.start]) if window is not None else None,
                              bool(controlled))
    report = {
        "scenario": request.scenario or (rec.scenario if rec else signals.path.resolve().name),
        "sample_rate_hz": FS,
        "tones": rows_out,
        "convergence_s": report_float(_convergence(over_time, rows_out, outcome)),
        "loop": loop_statistics(signals),
        "control": outcome.as_dict(),
    }
    following = following_tones(signals, windows, configured)
    if following:
        report["following_tones"] = following
    sensitivity, curves = sensitivity_comparison(
        signals, windows, controlled, tones,
        oscillators_moved_hz(signals, configured, [index[w] for w in windows.values()]))
    if sensitivity:
        report["sensitivity"] = sensitivity
    harmonics_of = (request.harmonics_of_hz if request.harmonics_of_hz is not None
                    else (rec.harmonics_of_hz if rec else 0.0))
    harmonics = None
    if harmonics_of and harmonics_of > 0.0:
        rows = windows["uncontrolled"]
        harmonics = report_jsonable(spectrum.harmonic_distortion(
            z[rows], FS, harmonics_of, segment_s=min(spectrum.DEFAULT_SEGMENT_S,
                                                     (rows.stop - rows.start) / FS)))
    details = _details(signals, levels, tones, notes, windows, index, over_time,
                       (ident, ident_source), harmonics)
    return Analysis(report, details, z, windows, index, over_time, ident,
                    rec.paper() if rec else {}, harmonics, curves, controlled, configured)


def _convergence(over_time: dict, rows: list[dict], outcome: ControlOutcome) -> float:
    """``convergence_s`` of the controlled tones control reduced, NaN (absent) otherwise.

    Without control in force in the controlled window there is nothing that converged; a
    tone reduced by less than the convergence tolerance was within it from the start (its
    'convergence' would be the first level's time, not control's).
    """
    if not outcome.in_force:
        return math.nan
    reduced = [row["frequency_hz"] for row in rows if row["controlled"]
               and (row["reduction_db"] or 0.0) >= spectrum.CONVERGENCE_TOLERANCE_DB]
    return convergence_s(over_time, reduced) if reduced else math.nan


def _fmt_tones(tones: list[float]) -> str:
    return ", ".join(f"{f:g}" for f in tones) + " Hz"


def tone_rows(tones: list[float], controlled: list[float], levels: dict) -> list[dict]:
    """report.json's ``tones`` rows from :func:`tone_levels` of each window (by name)."""
    rows = []
    for k, f in enumerate(tones):
        unc, _, unc_floor = (levels["uncontrolled"][i][k] for i in range(3))
        ctl = levels["controlled"][0][k] if "controlled" in levels else None
        ctl_floor = levels["controlled"][2][k] if "controlled" in levels else None
        rows.append({"frequency_hz": float(f),
                     "controlled": bool(any(abs(f - c) < 1e-6 for c in controlled)),
                     "uncontrolled_db": round(unc, 2),
                     "controlled_db": None if ctl is None else round(ctl, 2),
                     "reduction_db": None if ctl is None else round(round(unc, 2)
                                                                    - round(ctl, 2), 2),
                     "at_noise_floor": {"uncontrolled": unc_floor, "controlled": ctl_floor}})
    return rows


def _strongest_peaks(z: np.ndarray, count: int = 3) -> list[float]:
    """Frequencies (Hz, to 0.1 Hz) of the strongest spectral peaks above 5 Hz."""
    f, psd = spectrum.power_spectral_density(z - z.mean(), FS, segment_s=min(
        DEFAULT_WINDOW_S, z.size / FS))
    psd = np.where(f > 5.0, psd, 0.0)
    peaks: list[float] = []
    for k in np.argsort(psd)[::-1]:
        if all(abs(f[k] - p) > 2.0 for p in peaks):
            peaks.append(float(round(f[k], 1)))
        if len(peaks) == count:
            break
    return sorted(peaks)


def loop_statistics(signals: BagSignals) -> dict[str, Any]:
    """The ``loop`` block: from the driver's diagnostics, else estimated from the bag.

    ``missed_samples`` adds the samples of the run ``[0, samples)`` absent from
    ``/pph/accel`` in the bag to the driver's own count (in realtime: the samples whose
    commands came late); ``notch_missed_samples``: the samples the notch controller never
    received (its gaps); ``forecast_rows``: the late commands a controller's forecast stood
    in for (a realtime driver's ``<stream>_forecast_applied``, summed over the streams);
    ``stand_in_samples``: the due samples where a force no controller computed went in (a
    realtime driver's count, ``core/loop/stand_in_log``); ``control_on_samples`` and
    ``control_on_missed_samples``: a realtime driver's samples and late commands from its
    first report at or after control-on (``control_on_counted_from``) to its last
    (``analysis/late_commands``: apart from the start, where the notch analyses its
    identification on its loop thread).
    """
    accel, st = signals.accel, signals.driver_status
    run = signals.run_samples()
    missing = accel.missing_in(run)
    notch = signals.notch_statuses[-1] if signals.notch_statuses else {}
    own = {"notch_missed_samples": int(notch["missed_samples"])} \
        if "missed_samples" in notch else {}
    forecasts = [int(v) for k, v in st.items() if k.endswith("_forecast_applied")]
    if any(forecasts):
        own["forecast_rows"] = sum(forecasts)
    if "stand_in_samples" in st:
        own["stand_in_samples"] = int(st["stand_in_samples"])
    if st.get("mode") == "realtime" and signals.control_on_sample is not None:
        since = late_since(signals.driver_statuses, signals.control_on_sample)
        if since is not None:
            (own["control_on_counted_from"], own["control_on_samples"],
             own["control_on_missed_samples"]) = since
    if st:
        return {"mode": st.get("mode", "unknown"),
                "samples": run,
                "missed_samples": int(st.get("missed_samples", 0)) + missing,
                "rate_hz": report_float(float(st.get("rate_hz", "nan"))),
                **{k: report_float(float(st.get(k, "nan"))) for k in LOOP_KEYS}, **own}
    stamps = accel.timestamp_ns
    span_s = (stamps[-1] - stamps[0]) * 1e-9 if stamps.size > 1 else 0.0
    latency = _bag_latency_ms(signals)
    return {"mode": "unknown", "samples": run, "missed_samples": missing,
            "rate_hz": report_float((stamps.size - 1) / span_s if span_s > 0 else math.nan),
            "latency_ms_p50": report_float(np.percentile(latency, 50) if latency.size else
                                          math.nan),
            "latency_ms_p99": report_float(np.percentile(latency, 99) if latency.size else
                                          math.nan)}


def _bag_latency_ms(signals: BagSignals) -> np.ndarray:
    """Bag-timestamp delay from accel(n) to notch_command(n) (a recorder's view)."""
    cmd = signals.series.get("/pph/notch_command")
    if cmd is None or cmd.timestamp_ns.size == 0 or signals.accel.timestamp_ns.size == 0:
        return np.zeros(0)
    common, ia, ic = np.intersect1d(signals.accel.sample_index, cmd.sample_index,
                                    return_indices=True)
    if common.size == 0:
        return np.zeros(0)
    return (cmd.timestamp_ns[ic] - signals.accel.timestamp_ns[ia]) * 1e-6


def _details(signals: BagSignals, levels: dict, tones: list[float], notes: list[str],
             windows: dict[str, slice], index: np.ndarray, over_time: dict,
             identification: tuple[list[tuple[int, int]], str],
             harmonics: dict | None) -> dict[str, Any]:
    run = signals.run_samples()
    details: dict[str, Any] = {
        "bag": str(signals.path),
        "run_record": asdict(signals.record) if signals.record else None,
        "control_on_sample": signals.control_on_sample,
        "control_on_source": signals.control_source,
        "identification": {"intervals": [list(i) for i in identification[0]],
                           "source": identification[1],
                           "settle_s": IDENTIFICATION_SETTLE_S},
        "windows": {name: {"first_sample": int(index[rows.start]) if rows.stop > rows.start
                           else None,
                           "samples": rows.stop - rows.start} for name, rows in windows.items()},
        "levels_db_re_1g": {name: {"frequency_hz": tones, "level": lv, "noise_floor": fl,
                                   "at_noise_floor": af}
                            for name, (lv, fl, af) in levels.items()},
        "convergence": {f"{f:g}": {"convergence_s": v["convergence_s"],
                                   "final_level_db": v["final_level_db"],
                                   "level_window_s": v["window_s"]}
                        for f, v in over_time.items()},
        "run_samples": run,
        "topics": {t: {"samples": len(s), "missing_samples": s.missing_in(run),
                       "first_sample": s.first_sample,
                       "duplicate_samples": s.duplicate_samples,
                       "invalid_messages": s.invalid_messages, "index_source": s.index_source}
                   for t, s in signals.series.items()},
        "undecodable_messages": signals.bad_messages,
        "notes": notes,
        "driver_status": signals.driver_status,
        "notch_status": signals.notch_statuses[-1] if signals.notch_statuses else {},
    }
    if harmonics is not None:
        details["harmonic_distortion"] = harmonics
    return details
