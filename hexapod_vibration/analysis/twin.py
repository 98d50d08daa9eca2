"""A run measured against its uncontrolled twin: the same scenario with control never on.

A lockstep run is deterministic: run again with the same seeds and identification but with
control never switched on, it is sample-for-sample the same until control-on, and after it
exactly "no control" at the same times. So the controlled window of the run (``BAG``) is
compared with the same samples of the twin (``TWIN``) instead of with a window before
control: a moving tone, a drift or the noise floor is compared at the same time.

- The check (:func:`check_twin`): the same run length, no control-on in the twin, and the
  top plate's z acceleration identical (to ``IDENTICAL_M_S2``) on every sample before
  control-on; otherwise :class:`NotATwin`.
- ``tones``: each report tone's level (:func:`~hexapod_vibration.analysis.levels.tone_levels`)
  in the controlled window and in the twin's same samples; a tone whose recorded track
  moved over the window is measured in a band following it (both signals dechirped along
  the same track of the run, :func:`~hexapod_vibration.analysis.moving_tones.dechirp`).
- ``following_over_time``: each tracked tone's reduction in consecutive windows of
  ``segment_s`` from control-on to the end of the run, and likewise every other recorded
  true disturbance line (a rotor's orders: the bank's harmonics follow them); windows
  whose controlled level is at the noise floor are flagged (their reduction is a bound).
- ``bands``: third-octave band levels (lines included: a band's whole level) over the
  controlled window, controlled minus twin, and the contract's ``never_worse``;
  ``bands_over_time``: the same in windows of the controlled window's length sliding from
  control-on, with the worst of them.
- ``sensitivity``: the measured |S(f)|, H1 from twin z to controlled z
  (:func:`~hexapod_vibration.analysis.moving_tones.transfer_function_db`), against the
  recorded prediction near the tones
  (:func:`~hexapod_vibration.analysis.sensitivity_check.prediction_difference`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hexapod_vibration.analysis import moving_tones
from hexapod_vibration.analysis.bag_signals import FS, BagSignals
from hexapod_vibration.analysis.following import SNAP_HZ, tone_tracks
from hexapod_vibration.analysis.levels import tone_levels
from hexapod_vibration.analysis.report import Analysis
from hexapod_vibration.analysis.report_tables import level_text, reduction_text
from hexapod_vibration.analysis.sensitivity_check import (
    oscillators_moved_hz,
    prediction_difference,
    recorded_prediction,
)
from hexapod_vibration.contract import DISTURBANCE_FREQUENCIES_TOPIC, NEVER_WORSE_DB
from hexapod_vibration.core import spectrum
from hexapod_vibration.json_values import json_float

IDENTICAL_M_S2 = 1e-9
"""Before control-on the twin's z acceleration equals the run's to this (m/s^2)."""
DEFAULT_SEGMENT_S = 1.0
"""``following_over_time`` window (s)."""
BAND_LOW_HZ, BAND_HIGH_HZ = 5.0, 450.0
"""Third-octave band centres compared (Hz)."""
BAND_SEGMENT_S, BAND_WINDOW = 4.0, "hann"
"""Welch segment (s, 50 % overlap) and window of the third-octave comparison.

A band needs no line resolution, but an averaged estimate: the controlled run's floor
(sensor noise, quantisation) is not the twin's realization, and one 10 s Blackman-Harris
segment scattered by +-0.7 dB on floor-level bands (Table 1, core loop, the same pair of
signals: 63 Hz band -0.70 dB with it, +0.13 dB with 4 s Hann segments; through the graph
+1.11 against +0.63 dB), enough to flip the never-worse verdict at its 1 dB margin."""
BANDS_STEP_S = 1.0
"""Step (s) of the windows of ``bands_over_time`` (each as long as the report's window)."""
DIGITS = 2
STEADY_TRACK_HZ = 1e-6
"""A track within this of its report tone over the whole window is held there (Hz)."""


class NotATwin(ValueError):
    """The twin bag is not the same run with control never on."""


def _round(value: float) -> float | None:
    return json_float(value, DIGITS)


def check_twin(signals: BagSignals, twin: BagSignals) -> int:
    """The run's control-on sample, once ``twin`` is shown to be its twin; else NotATwin."""
    def refuse(why: str) -> NotATwin:
        return NotATwin(f"{twin.path} is not this run's twin: {why}")

    on = signals.control_on_sample
    if on is None:
        raise ValueError(f"{signals.path}: control never went on: nothing to compare with a "
                         "twin")
    samples, twin_samples = signals.run_samples(), twin.run_samples()
    if samples != twin_samples:
        raise refuse(f"{twin_samples} samples, the run has {samples}")
    if twin.control_on_sample is not None and twin.control_on_sample < samples:
        raise refuse(f"its control went on at sample {twin.control_on_sample}")
    index, twin_index = signals.accel.sample_index, twin.accel.sample_index
    common, rows, twin_rows = np.intersect1d(index[index < on], twin_index,
                                             return_indices=True)
    if common.size == 0:
        raise refuse(f"no sample before control-on (sample {on}) in both bags")
    difference = np.abs(signals.z[rows] - twin.z[twin_rows])
    worst = int(np.argmax(difference))
    if difference[worst] > IDENTICAL_M_S2:
        raise refuse(f"z acceleration differs by {difference[worst]:.3g} m/s^2 at sample "
                     f"{int(common[worst])}, before control-on (sample {on})")
    return on


def _rows_of(signals: BagSignals, samples: np.ndarray) -> tuple[np.ndarray, int]:
    """(rows of ``signals`` holding ``samples``, how many of the samples it misses)."""
    index = signals.accel.sample_index
    if not index.size:
        return np.zeros(samples.size, dtype=np.int64), samples.size
    rows = np.clip(np.searchsorted(index, samples), 0, index.size - 1)
    return rows, int(np.count_nonzero(index[rows] != samples))


def _twin_rows(twin: BagSignals, samples: np.ndarray, what: str) -> np.ndarray:
    """The twin's rows holding ``samples``; ValueError if the twin misses any of them."""
    rows, missing = _rows_of(twin, samples)
    if missing:
        raise ValueError(f"{twin.path}: misses {missing} samples of {what}")
    return rows


def _row(frequency_hz: float, controlled: bool, band: str, ctl: tuple, twin: tuple
         ) -> dict[str, Any]:
    """A ``tones`` row from (level, floor flag) of the run and of the twin (dB re 1 g)."""
    return {"frequency_hz": float(frequency_hz), "controlled": controlled, "band": band,
            "controlled_db": _round(ctl[0]), "twin_db": _round(twin[0]),
            "reduction_db": _round(round(twin[0], DIGITS) - round(ctl[0], DIGITS)),
            "at_noise_floor": {"controlled": ctl[1], "twin": twin[1]}}


def _following_level(x: np.ndarray, track_hz: np.ndarray) -> tuple[float, bool]:
    """(level dB re 1 g, at floor) in a band following ``track_hz`` (Hz per sample)."""
    y, f_ref = moving_tones.dechirp(x, track_hz, FS)
    level, _, at_floor = tone_levels(y, [f_ref])
    return level[0], at_floor[0]


def compare(signals: BagSignals, twin: BagSignals, result: Analysis,
            segment_s: float = DEFAULT_SEGMENT_S) -> dict[str, Any]:
    """report.json's ``twin`` section (see the module docstring); adds the H1 curve.

    Raises:
        NotATwin: ``twin`` is not this run's twin.
        ValueError: no controlled window, or the twin misses samples of it.
    """
    on = check_twin(signals, twin)
    if "controlled" not in result.windows:
        raise ValueError(f"{signals.path}: no controlled window to compare with the twin")
    window = result.windows["controlled"]
    index = signals.accel.sample_index
    samples = index[window]
    first, stop = int(samples[0]), int(samples[-1]) + 1
    z_ctl = signals.z[window]
    z_twin = twin.z[_twin_rows(twin, samples, f"the controlled window [{first}, {stop})")]
    tracks = [(f, t) for f, t in zip(result.tracked_hz, tone_tracks(signals, result.tracked_hz),
                                     strict=True) if t is not None]
    others = _other_lines(signals, tracks)
    section: dict[str, Any] = {
        "bag": str(twin.path), "control_on_sample": on,
        "window": {"first_sample": first, "samples": stop - first},
        "tones": _tones(result, z_ctl, z_twin, samples, tracks,
                        _report_lines(result, others, on)),
        "following_over_time": _over_time(signals, twin, on, tracks + others, segment_s),
        "bands": _bands(z_ctl, z_twin),
        "bands_over_time": _bands_over_time(signals, twin, on, (stop - first) / FS),
    }
    sensitivity = _sensitivity(signals, result, z_ctl, z_twin,
                               oscillators_moved_hz(signals, result.tracked_hz, [samples]))
    if sensitivity:
        section["sensitivity"] = sensitivity
    return section


def _tones(result: Analysis, z_ctl: np.ndarray, z_twin: np.ndarray, samples: np.ndarray,
           tracks: list[tuple[float, tuple[str, np.ndarray, np.ndarray]]],
           lines: list[tuple[float, tuple[str, np.ndarray, np.ndarray]]] = ()
           ) -> list[dict[str, Any]]:
    """Fixed-band rows per report tone; a tone whose track left it gets a following band.

    A track that moved over the window, or held still away from its report tone (a
    spin-up at its final speed: the tone at 50 Hz, its report tone 30 Hz). ``tracks``: the
    notch's tones (controlled); ``lines``: other disturbance lines named by the report
    tone they started on (:func:`_report_lines`), controlled as that tone's row says.
    """
    report_rows = result.report["tones"]
    tones = [r["frequency_hz"] for r in report_rows]
    segment = min(spectrum.DEFAULT_SEGMENT_S, z_ctl.size / FS)
    ctl, twin = tone_levels(z_ctl, tones, segment), tone_levels(z_twin, tones, segment)
    rows = [_row(f, r["controlled"], "fixed", (ctl[0][k], ctl[2][k]),
                 (twin[0][k], twin[2][k])) for k, (f, r) in enumerate(zip(tones, report_rows,
                                                                           strict=True))]
    entries = [(f, track, True) for f, track in tracks] + [(f, track, None) for f, track in lines]
    for nominal, (topic, at, hz), controlled in entries:
        track_hz = moving_tones.track_on_samples(at, hz, samples)
        same = [k for k, f in enumerate(tones) if abs(f - nominal) <= SNAP_HZ]
        if any(np.max(np.abs(track_hz - f)) <= STEADY_TRACK_HZ for f in tones):
            continue                            # held on a report tone: its fixed band
        if controlled is None:
            controlled = bool(report_rows[same[0]]["controlled"])
        row = _row(nominal, controlled, "following", _following_level(z_ctl, track_hz),
                   _following_level(z_twin, track_hz))
        row.update(source=topic, frequency_span_hz=[round(float(track_hz.min()), 4),
                                                    round(float(track_hz.max()), 4)])
        if same:
            rows[same[0]] = row
        else:
            rows.append(row)
    return rows


def _report_lines(result: Analysis,
                  others: list[tuple[float, tuple[str, np.ndarray, np.ndarray]]], on: int
                  ) -> list[tuple[float, tuple[str, np.ndarray, np.ndarray]]]:
    """The other lines that sat on a report tone at control-on, named by that tone (Hz).

    A rotor's orders 2 and 3 in the notch's bank (``harmonics``) start on the report tones
    60 and 90 Hz and end at 100 and 150 Hz: their rows follow them as the fundamental's does.
    """
    tones = [r["frequency_hz"] for r in result.report["tones"]]
    out = []
    for _, (topic, at, hz) in others:
        at_on = float(moving_tones.track_on_samples(at, hz, np.array([on]))[0])
        near = [f for f in tones if abs(f - at_on) <= SNAP_HZ]
        if near:
            out.append((near[0], (topic, at, hz)))
    return out


def _other_lines(signals: BagSignals,
                 tracks: list[tuple[float, tuple[str, np.ndarray, np.ndarray]]]
                 ) -> list[tuple[float, tuple[str, np.ndarray, np.ndarray]]]:
    """Every other recorded true disturbance line (a rotor's orders, the shaker's tones).

    The columns of ``/pph/disturbance_frequencies`` no controlled tone follows, each named
    by its median frequency (Hz): a harmonic in the notch's bank (``harmonics``) or a line
    nobody cancels is measured the same way, in a band following it.
    """
    truth = signals.frequencies.get(DISTURBANCE_FREQUENCIES_TOPIC)
    if truth is None:
        return []
    at, table = truth
    used = [hz for _, (topic, _, hz) in tracks if topic == DISTURBANCE_FREQUENCIES_TOPIC]
    out = []
    for column in table.T:
        if np.any(np.isfinite(column)) and not any(
                np.array_equal(column, hz, equal_nan=True) for hz in used):
            out.append((float(np.nanmedian(column)),
                        (DISTURBANCE_FREQUENCIES_TOPIC, at, column)))
    return out


def _paired_windows(signals: BagSignals, twin: BagSignals, on: int, width: int, step: int
                    ) -> tuple[list[tuple[int, np.ndarray, np.ndarray]], int]:
    """Windows of ``width`` samples every ``step`` from ``on``, each whole in both bags.

    Returns ``([(first sample, run rows, twin rows)], skipped)``, to the end of the run. A
    window with a sample missing from either bag is left out (counted in ``skipped``).
    """
    windows, skipped = [], 0
    for a in range(on, signals.run_samples() - width + 1, step):
        samples = np.arange(a, a + width)
        (rows, missing), (twin_rows, twin_missing) = (_rows_of(signals, samples),
                                                      _rows_of(twin, samples))
        if missing or twin_missing:
            skipped += 1
        else:
            windows.append((a, rows, twin_rows))
    return windows, skipped


def _over_time(signals: BagSignals, twin: BagSignals, on: int,
               tracks: list[tuple[float, tuple[str, np.ndarray, np.ndarray]]],
               segment_s: float) -> list[dict[str, Any]]:
    """Per tracked tone: its reduction (dB) in consecutive ``segment_s`` windows from ``on``.

    A window whose controlled level is at its noise floor gives only a lower bound on the
    reduction (the line is below what the window resolves: :func:`tone_levels`); one whose
    twin level is at the floor has no line to reduce. ``at_noise_floor`` flags both per
    window; ``min_measured_reduction_db`` is the smallest reduction of the windows where
    neither is at the floor (None if there is none), ``min_reduction_db`` and
    ``median_reduction_db`` are over every window, as before.
    """
    width = int(round(segment_s * FS))
    windows, skipped = _paired_windows(signals, twin, on, width, width)
    out = []
    for nominal, (topic, at, hz) in tracks:
        points, floor_ctl, floor_twin = [], [], []
        for a, rows, twin_rows in windows:
            track_hz = moving_tones.track_on_samples(at, hz, np.arange(a, a + width))
            level_ctl, at_floor_ctl = _following_level(signals.z[rows], track_hz)
            level_twin, at_floor_twin = _following_level(twin.z[twin_rows], track_hz)
            points.append([round(a / FS, 3), _round(level_twin - level_ctl)])
            floor_ctl.append(at_floor_ctl)
            floor_twin.append(at_floor_twin)
        values = [p[1] for p in points]
        measured = [v for v, c, t in zip(values, floor_ctl, floor_twin, strict=True)
                    if not (c or t)]
        out.append({"frequency_hz": float(nominal), "source": topic,
                    "segment_s": float(segment_s), "reduction_db": points,
                    "at_noise_floor": {"controlled": floor_ctl, "twin": floor_twin},
                    "min_reduction_db": _round(min(values)) if values else None,
                    "median_reduction_db": _round(float(np.median(values))) if values
                    else None,
                    "min_measured_reduction_db": _round(min(measured)) if measured else None,
                    "windows_at_floor": int(np.count_nonzero(
                        np.logical_or(floor_ctl, floor_twin))),
                    "windows_skipped": skipped})
    return out


def _bands_over_time(signals: BagSignals, twin: BagSignals, on: int, window_s: float
                     ) -> dict[str, Any]:
    """The third-octave comparison (:func:`_bands`) in sliding ``window_s`` windows.

    The windows start every :data:`BANDS_STEP_S` from control-on to the end of the run:
    the contract's never-worse over every span of that length, not only over the report's
    window (the start of control, a fade, a spin-up's start lie before it).
    """
    width = int(round(window_s * FS))
    windows, skipped = _paired_windows(signals, twin, on, width,
                                       int(round(BANDS_STEP_S * FS)))
    starts, rises, where = [], [], []
    for a, rows, twin_rows in windows:
        bands = _bands(signals.z[rows], twin.z[twin_rows])
        starts.append(round(a / FS, 3))
        rises.append(bands["largest_rise_db"])
        where.append(bands["largest_rise_at_hz"])
    finite = [k for k, r in enumerate(rises) if r is not None]
    worst = max(finite, key=lambda k: rises[k]) if finite else None
    return {"window_s": float(window_s), "step_s": BANDS_STEP_S, "start_s": starts,
            "largest_rise_db": rises, "largest_rise_at_hz": where,
            "worst_start_s": starts[worst] if worst is not None else None,
            "worst_rise_db": rises[worst] if worst is not None else None,
            "worst_rise_at_hz": where[worst] if worst is not None else None,
            "never_worse": bool(rises[worst] <= NEVER_WORSE_DB) if worst is not None
            else None,
            "windows_skipped": skipped}


def _bands(z_ctl: np.ndarray, z_twin: np.ndarray) -> dict[str, Any]:
    """Third-octave levels (lines included) over the controlled window, run and twin."""
    bands = spectrum.third_octave_bands_hz(BAND_LOW_HZ, BAND_HIGH_HZ)
    segment = min(BAND_SEGMENT_S, z_ctl.size / FS)
    ctl = spectrum.band_levels_db(z_ctl - z_ctl.mean(), FS, bands, segment_s=segment,
                                  window=BAND_WINDOW)
    off = spectrum.band_levels_db(z_twin - z_twin.mean(), FS, bands, segment_s=segment,
                                  window=BAND_WINDOW)
    rise = ctl - off
    ok = np.isfinite(rise)
    k = int(np.flatnonzero(ok)[np.argmax(rise[ok])]) if ok.any() else -1
    largest = float(rise[k]) if k >= 0 else math.nan
    return {"centre_hz": [round(float(f), 2) for f in bands[:, 0]],
            "controlled_db": [_round(v) for v in ctl], "twin_db": [_round(v) for v in off],
            "rise_db": [_round(v) for v in rise],
            "largest_rise_db": _round(largest),
            "largest_rise_at_hz": round(float(bands[k, 0]), 2) if k >= 0 else None,
            "never_worse": bool(largest <= NEVER_WORSE_DB) if k >= 0 else None}


def _sensitivity(signals: BagSignals, result: Analysis, z_ctl: np.ndarray,
                 z_twin: np.ndarray, moved_hz: float) -> dict[str, Any]:
    """H1 (twin z -> controlled z) against the recorded prediction; adds the curve.

    ``moved_hz``: how far an oscillator ran from its configured tone over the window (Hz); see
    :func:`~hexapod_vibration.analysis.sensitivity_check.prediction_difference`.
    """
    f, measured, coherence = moving_tones.transfer_function_db(z_twin, z_ctl, FS)
    result.sensitivity_curves["twin_frequency_hz"] = f
    result.sensitivity_curves["twin_db"] = measured
    prediction = recorded_prediction(signals)
    if prediction is None:
        return {}
    sample, view, grid, predicted = prediction
    tones = [r["frequency_hz"] for r in result.report["tones"]]
    segment_s = moving_tones.ratio_segment_s(z_ctl, z_twin, FS)
    return {"estimate": "H1 = Pxy / Pxx, twin z -> controlled z",
            "view": view.removesuffix("_db"), "prediction_sample": sample,
            **prediction_difference(f, measured, grid, predicted, result.controlled_hz, tones,
                                    segment_s, coherence, moved_hz)}


def _over_time_line(tone: dict[str, Any]) -> str:
    """One console line for a ``following_over_time`` entry (">=": at the noise floor)."""
    at_floor = [c or t for c, t in zip(tone["at_noise_floor"]["controlled"],
                                       tone["at_noise_floor"]["twin"], strict=True)]
    values = [p[1] for p in tone["reduction_db"]]
    lowest = values.index(tone["min_reduction_db"])
    bound = ">= " if at_floor[lowest] else ""
    text = (f"following {tone['frequency_hz']:g} Hz over {tone['segment_s']:g} s windows from "
            f"control-on: min {bound}{tone['min_reduction_db']:.1f} dB, median "
            f"{tone['median_reduction_db']:.1f} dB ({len(values)} windows")
    if not tone["windows_at_floor"]:
        return text + ")"
    measured = tone["min_measured_reduction_db"]
    above = "none" if measured is None else f"min {measured:.1f} dB"
    return (text + f", {tone['windows_at_floor']} at the noise floor; above it: {above})")


def format_twin(report: dict[str, Any]) -> str:
    """The twin comparison as a table (``format_table``'s layout) and three summary lines."""
    section = report.get("twin")
    if not section:
        return ""
    lines = [f"{report['scenario']}  (against its twin without control, same samples; "
             "20 log10(a_rms / 1 g), z-axis; * = notch tone)",
             f"{'Frequency':>10} {'band':>9} {'twin':>17} {'controlled':>17} {'reduction':>10}"]
    for row in section["tones"]:
        floor = row["at_noise_floor"]
        mark = "*" if row["controlled"] else " "
        reduction = reduction_text({"reduction_db": row["reduction_db"], "at_noise_floor": {
            "controlled": floor["controlled"], "uncontrolled": floor["twin"]}})
        lines.append(f"{row['frequency_hz']:>8.1f}Hz{mark}{row['band']:>9}"
                     f"{level_text(row['twin_db'], floor['twin']):>18} "
                     f"{level_text(row['controlled_db'], floor['controlled']):>17} "
                     f"{reduction:>10}")
    lines.extend(_over_time_line(tone) for tone in section["following_over_time"]
                 if tone["min_reduction_db"] is not None)
    bands = section["bands"]
    if bands["largest_rise_db"] is not None:
        lines.append(f"third-octave bands {BAND_LOW_HZ:g}-{BAND_HIGH_HZ:g} Hz: largest rise "
                     f"{bands['largest_rise_db']:+.2f} dB at {bands['largest_rise_at_hz']:g} Hz"
                     f" (never worse than off: {'yes' if bands['never_worse'] else 'NO'})")
    sliding = section.get("bands_over_time")
    if sliding and sliding["worst_rise_db"] is not None:
        start = sliding["worst_start_s"]
        lines.append(f"  in every {sliding['window_s']:g} s window from control-on (step "
                     f"{sliding['step_s']:g} s): worst {sliding['worst_rise_db']:+.2f} dB at "
                     f"{sliding['worst_rise_at_hz']:g} Hz, {start:g}-"
                     f"{start + sliding['window_s']:g} s (never worse than off: "
                     f"{'yes' if sliding['never_worse'] else 'NO'})")
    sens = section.get("sensitivity")
    if sens and sens.get("not_compared"):
        lines.append(f"sensitivity H1 not compared with the prediction: {sens['not_compared']}")
    elif sens and sens["near_tones_points"]:
        lines.append(f"sensitivity H1 vs predicted within {moving_tones.NEAR_TONE_HZ:g} Hz of the"
                     f" tones: rms {sens['near_tones_rms_difference_db']:.2f} dB, max "
                     f"{sens['near_tones_max_difference_db']:.2f} dB "
                     f"({sens['near_tones_points']} points)")
    return "\n".join(lines)

