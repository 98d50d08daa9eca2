"""From a rosbag2 bag of the contract topics to the paper's tables and figures.

No ROS import: bags are read with rosbags (:mod:`hexapod_vibration.analysis.bag_io`), in one
streaming pass that keeps only what the report needs (the top plate's z acceleration per
sample, the sample accounting of every topic, decimated eddy gaps and notch weights), so
memory does not grow with anything but 8 bytes per accelerometer sample.

Every value sits on its loop sample (in-band index, or the bag timestamps on the 1 kHz
grid); samples are counted from the run's sample 0, missing ones are never interpolated.

The level of a tone is ``20 log10(a_rms / 1 g)`` of its component in the top plate's z-axis
acceleration, recovered from the six accelerometers through the Stewart Jacobian, from a
Blackman-Harris Welch spectrum (:mod:`hexapod_vibration.core.spectrum`). A tone below the
local noise floor is reported at the floor's level and flagged ``at_noise_floor``, so a
reduction is never larger than the floor lets us see.

What an experiment recorded about its run (:class:`RunRecord`, in the bag's
``metadata.yaml`` ``custom_data``) sets the scenario name, tones, windows and the paper's
column, so ``analyze BAG`` gives exactly the experiment's report. Spectrum windows never
include the notch controller's plant identification (its test tones): the identification
interval comes from the notch's ``/diagnostics``, else from its reported state, else from
the run record.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexapod_vibration.analysis import bag_io, moving_tones
from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    DRIVER_STATUS,
    NOTCH_FREQUENCIES_TOPIC,
    NOTCH_STATUS,
    SAMPLE_RATE_HZ,
    NotchState,
)
from hexapod_vibration.core import spectrum
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.geometry import CubicHexapodGeometry
from hexapod_vibration.core.model.sensors import EddySensorArray
from hexapod_vibration.json_values import json_float, jsonable
from hexapod_vibration.json_values import write_json as write_json_values

FS = SAMPLE_RATE_HZ
DEFAULT_WINDOW_S = 10.0
LOOP_KEYS = ("latency_ms_p50", "latency_ms_p99")
IDENTIFICATION_SETTLE_S = 0.5
"""Left out after an identification ends: the plant's response to its test tones rings down."""
CONVERGENCE_LEAD_S = 2.0
"""Level-over-time curves start this long before control-on."""
MIN_BINS_PER_SPACING = 9
"""A spectrum separates two lines ``d`` Hz apart when it has at least 9 bins per ``d``
(main lobe 4 bins each side plus a half-bin offset and margin, see core.spectrum): a window
shorter than ``9 / d`` s cannot give the tone table."""
POSE_BLOCK = 100
"""Pointing figure: the pose's mean and RMS deviation per block of 100 samples (0.1 s)."""
COMMAND_EVERY = 10
"""Notch-command timestamps kept (for a bag-timestamp latency estimate): every 10th."""
WEIGHTS_EVERY = 10
"""Notch weights kept for the convergence figure: every 10th message (10 Hz)."""


class WindowTooShort(ValueError):
    """A spectrum window whose usable (gap-free, identification-free) run is too short."""


# ---------------------------------------------------------------------------- run record
@dataclass(frozen=True)
class RunRecord:
    """What the experiment runner recorded about a run, in the bag's ``custom_data``.

    Sample numbers are loop samples (1 kHz); -1 means none.
    """

    scenario: str
    report_tones_hz: list[float]
    notch_tones_hz: list[float]
    window_s: float
    samples: int
    control_on_sample: int = -1
    identify_at_sample: int = -1
    identification_samples: int = 0
    harmonics_of_hz: float = 0.0
    paper_reduction_db: dict[str, float] = field(default_factory=dict)
    mode: str = "lockstep"

    def to_json(self) -> str:
        """One-line JSON (the ``custom_data`` value)."""
        return json.dumps(asdict(self), separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> RunRecord:
        """Parse :meth:`to_json`; ValueError if it is not a run record."""
        try:
            data = json.loads(text)
            return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})
        except (TypeError, KeyError, json.JSONDecodeError) as err:
            raise ValueError(f"not a run record: {err}") from None

    def paper(self) -> dict[float, float]:
        """The paper's reductions (dB) by frequency (Hz)."""
        return {float(k): float(v) for k, v in self.paper_reduction_db.items()}


# ---------------------------------------------------------------------------- bag reading
@dataclass
class BagSignals:
    """What the analysis needs from one bag, sample-indexed.

    ``series["/pph/accel"].values`` holds the top plate's z acceleration (m/s^2, one
    column); ``series["/pph/eddy"]`` per block of ``POSE_BLOCK`` samples the mean pose
    (m, rad; 6 columns) then its RMS deviation (6 columns); the other topics only their
    sample accounting.
    """

    path: Path
    series: dict[str, bag_io.StrutSeries]
    driver_status: dict[str, str] = field(default_factory=dict)
    notch_statuses: list[dict[str, str]] = field(default_factory=list)
    weights_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 6, 2)))
    control_on_sample: int | None = None
    control_source: str = "none"
    record: RunRecord | None = None
    recovered: str = ""
    bad_messages: dict[str, int] = field(default_factory=dict)
    frequencies: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    """Recorded frequency topics: (sample index (N,), Hz (N, K)) (``BagContent.frequencies``)."""
    sensitivity: list[tuple[int, dict[str, np.ndarray]]] = field(default_factory=list)
    """Recorded ``/pph/notch_sensitivity`` predictions: (sample, {row: values})."""

    @property
    def accel(self) -> bag_io.StrutSeries:
        """The /pph/accel series (values: z acceleration, m/s^2)."""
        return self.series[bag_io.ACCEL_TOPIC]

    @property
    def z(self) -> np.ndarray:
        """Top plate z acceleration (m/s^2) per received sample."""
        return self.accel.values[:, 0]

    def notch_tones(self) -> list[float]:
        """Tones of the notch controller as it last reported them (Hz), or []."""
        for status in reversed(self.notch_statuses):
            if "tones_hz" in status:
                return [float(x) for x in json.loads(status["tones_hz"])]
        return []

    def run_samples(self) -> int:
        """Samples of the run: [0, this), from the driver and every topic's last sample."""
        last = max((s.last_sample for s in self.series.values()), default=-1)
        return max(int(self.driver_status.get("samples", 0) or 0), last + 1)


def z_columns(geometry: CubicHexapodGeometry) -> np.ndarray:
    """(6, 1) matrix: strut accelerations (m/s^2) @ it = top plate z acceleration."""
    return geometry.platform_from_struts(np.eye(6))[:, 2:3]


def pose_columns(model: ModelConfig) -> np.ndarray:
    """(6, 6) matrix: eddy-current gaps (m) @ it = the top plate's pose (m, rad)."""
    height = float(model.geometry.top_joints_m[0, 2])
    return EddySensorArray(model.eddy, height).pose(np.eye(6))


def load_signals(bag_path: str | Path, model: ModelConfig,
                 control_on_s: float | None = None) -> BagSignals:
    """Read the bag in one pass; find the run record and when control went on."""
    none = np.zeros((6, 0))
    keep = {topic: bag_io.Keep(columns=none, timestamps=False) for topic in bag_io.STRUT_TOPICS}
    keep[bag_io.ACCEL_TOPIC] = bag_io.Keep(columns=z_columns(model.geometry))
    keep["/pph/eddy"] = bag_io.Keep(columns=pose_columns(model), timestamps=False,
                                    block=POSE_BLOCK)
    keep["/pph/notch_command"] = bag_io.Keep(columns=none, every=COMMAND_EVERY)
    content = bag_io.read_bag(bag_path, keep, FS, weights_every=WEIGHTS_EVERY)
    signals = BagSignals(Path(bag_path), content.strut, recovered=content.recovered,
                         bad_messages=content.bad_messages, frequencies=content.frequencies,
                         sensitivity=content.sensitivity)
    for _, name, values in content.diagnostics:
        if name == DRIVER_STATUS:
            signals.driver_status = values
        elif name == NOTCH_STATUS:
            signals.notch_statuses.append(values)
    signals.weights_index, signals.weights = content.weights_index, content.weights
    if bag_io.RUN_RECORD_KEY in content.custom_data:
        signals.record = RunRecord.from_json(content.custom_data[bag_io.RUN_RECORD_KEY])
    _find_control_switch(signals, control_on_s, content.parameter_events)
    return signals


def _find_control_switch(signals: BagSignals, control_on_s: float | None,
                         events: list[tuple[int, Any]]) -> None:
    """Control-on sample: CLI value, notch diagnostics, parameter event, run record, none.

    ``/parameter_events`` carry only receive times; they are used (placed on the sample
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
    switched = [t for t, v in events if v is True]
    accel = signals.accel
    if switched and accel.timestamp_ns.size:
        nearest = min(int(np.searchsorted(accel.timestamp_ns, switched[-1])),
                      accel.timestamp_ns.size - 1)
        signals.control_on_sample = int(accel.sample_index[nearest])
        signals.control_source = "parameter event"
    elif signals.record is not None and signals.record.control_on_sample >= 0:
        signals.control_on_sample = signals.record.control_on_sample
        signals.control_source = "run record"


# ---------------------------------------------------------------------------- identification
def identification_intervals(signals: BagSignals) -> tuple[list[tuple[int, int]], str]:
    """Sample intervals ``[start, stop)`` of the notch's identifications, and their source.

    From the notch's ``identification_start_sample``/``identification_end_sample``
    (diagnostics); for older bags from its ``state`` (an "identifying" stretch, widened to
    the statuses either side of it); else from the run record's plan.
    """
    keyed = _intervals_from_keys(signals.notch_statuses)
    if keyed is not None:
        return keyed, "notch diagnostics"
    stated = _intervals_from_state(signals.notch_statuses)
    if stated:
        return stated, "notch state (diagnostics without identification samples)"
    rec = signals.record
    if rec is not None and rec.identify_at_sample >= 0 and rec.identification_samples > 0:
        return ([(rec.identify_at_sample, rec.identify_at_sample + rec.identification_samples)],
                "run record (planned)")
    return [], "none"


def _intervals_from_keys(statuses: list[dict[str, str]]) -> list[tuple[int, int]] | None:
    """Intervals from ``identification_start_sample``/``_end_sample``; None if never given.

    An identification still running in the last status it appears in is open-ended.
    """
    if not any("identification_start_sample" in st for st in statuses):
        return None
    ended: dict[int, int] = {}
    running: set[int] = set()
    for st in statuses:
        start = int(st.get("identification_start_sample", -1))
        end = int(st.get("identification_end_sample", -1))
        if start < 0:
            continue
        if end >= start:
            ended[start] = end + 1
        else:
            running.add(start)
    for start in running - set(ended):
        ended[start] = 2**62
    return sorted(ended.items())


def _intervals_from_state(statuses: list[dict[str, str]]) -> list[tuple[int, int]]:
    intervals = []
    before, inside = 0, False
    for st in statuses:
        sample = int(st.get("last_sample", -1))
        if st.get("state") == "identifying":
            inside = True
        elif inside:
            intervals.append((before, sample + 1))
            inside, before = False, sample
        else:
            before = max(sample, 0)
    if inside:
        intervals.append((before, 2**62))
    return intervals


# ---------------------------------------------------------------------------- windows
def required_window_s(tones: list[float]) -> float:
    """Shortest spectrum window (s) that separates the tones from each other and from DC."""
    f = np.sort(np.asarray(tones, dtype=float))
    spacing = float(np.min(np.diff(np.concatenate([[0.0], f])))) if f.size else 1.0
    return MIN_BINS_PER_SPACING / spacing


def choose_window(index: np.ndarray, start: int, stop: int,
                  excluded: list[tuple[int, int]]) -> tuple[slice, list[str]]:
    """Rows of the longest gap-free run in ``[start, stop)`` outside the excluded intervals.

    Returns the rows and notes on what was left out (missing samples, identification).
    """
    notes = []
    allowed = np.ones(max(stop - start, 0), dtype=bool)
    for a, b in excluded:
        lo, hi = max(a, start), min(b, stop)
        if lo < hi:
            allowed[lo - start:hi - start] = False
            notes.append(f"samples [{lo}, {hi}) left out: notch identification "
                         f"(+{IDENTIFICATION_SETTLE_S:g} s settling)")
    rows = np.flatnonzero((index >= start) & (index < stop))
    rows = rows[allowed[index[rows] - start]] if rows.size else rows
    if rows.size == 0:
        return slice(0, 0), [*notes, f"no usable samples in [{start}, {stop})"]
    breaks = np.flatnonzero(np.diff(index[rows]) != 1)
    bounds = np.concatenate([[0], breaks + 1, [rows.size]])
    longest = int(np.argmax(np.diff(bounds)))
    a, b = int(rows[bounds[longest]]), int(rows[bounds[longest + 1] - 1]) + 1
    present = np.count_nonzero((index >= start) & (index < stop))
    if present < stop - start:
        notes.append(f"window [{start}, {stop}) has {stop - start - present} missing samples")
    if b - a < stop - start:
        notes.append(f"used the longest usable run, samples [{int(index[a])}, "
                     f"{int(index[b - 1]) + 1}) ({(b - a) / FS:.3f} s of the "
                     f"{(stop - start) / FS:g} s window)")
    return slice(a, b), notes


def tone_levels(x: np.ndarray, tones: list[float], segment_s: float | None = None
                ) -> tuple[list[float], list[float], list[bool]]:
    """(level dB re 1 g, floor dB re 1 g, at-floor flag) per tone; level >= floor.

    ``segment_s``: Welch segment (s), default 10 s or the whole signal if shorter.
    """
    if segment_s is None:
        segment_s = min(spectrum.DEFAULT_SEGMENT_S, np.size(x) / FS)
    raw, floor = spectrum.tone_and_floor_db(x, FS, tones, segment_s=segment_s)
    at_floor = [bool(r < fl) for r, fl in zip(raw, floor, strict=True)]
    level = [float(max(r, fl)) for r, fl in zip(raw, floor, strict=True)]
    return level, [float(fl) for fl in floor], at_floor


# ---------------------------------------------------------------------------- analysis
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
        bag_io.BagError: too few accelerometer samples.
    """
    accel, rec = signals.accel, signals.record
    if len(accel) < 2:
        raise bag_io.BagError(f"{signals.path}: /pph/accel has {len(accel)} samples")
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
    windows = _windows(signals, index, window_s, excluded, notes)
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
    report = {
        "scenario": request.scenario or (rec.scenario if rec else signals.path.resolve().name),
        "sample_rate_hz": FS,
        "tones": rows_out,
        "convergence_s": _json_float(convergence_s(over_time, controlled)),
        "loop": loop_statistics(signals),
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
        harmonics = _jsonable(spectrum.harmonic_distortion(
            z[rows], FS, harmonics_of, segment_s=min(spectrum.DEFAULT_SEGMENT_S,
                                                     (rows.stop - rows.start) / FS)))
    details = _details(signals, levels, tones, notes, windows, index, over_time,
                       (ident, ident_source), harmonics)
    return Analysis(report, details, z, windows, index, over_time, ident,
                    rec.paper() if rec else {}, harmonics, curves, controlled, configured)


def _windows(signals: BagSignals, index: np.ndarray, window_s: float | None,
             excluded: list[tuple[int, int]], notes: list[str]) -> dict[str, slice]:
    """The uncontrolled (before control-on) and controlled (last) windows' rows."""
    end = signals.run_samples()
    on = signals.control_on_sample
    if on is None:
        width = int(round(window_s * FS)) if window_s else end
        spans = {"uncontrolled": (max(end - width, 0), end)}
    else:
        width = int(round((window_s or DEFAULT_WINDOW_S) * FS))
        spans = {"uncontrolled": (max(on - width, 0), on),
                 "controlled": (max(on, end - width), end)}
    windows = {}
    for name, (a, b) in spans.items():
        rows, window_notes = choose_window(index, a, b, excluded)
        notes.extend(f"{name}: {n}" for n in window_notes)
        windows[name] = rows
    return windows


SNAP_HZ = 0.05
"""A notch tone within half a 0.1 Hz bin of a reported tone is that tone (a tracked tone
ends a few mHz from the true frequency)."""


def snap_to_tones(controlled: list[float], tones: list[float]) -> list[float]:
    """The notch's tones, each replaced by the reported tone within ``SNAP_HZ`` of it."""
    snapped = []
    for c in controlled:
        near = [t for t in tones if abs(t - c) <= SNAP_HZ]
        snapped.append(min(near, key=lambda t: abs(t - c)) if near else float(c))
    return snapped


def configured_tones(signals: BagSignals, controlled: list[float]) -> list[float]:
    """The notch's configured tones (Hz), one per ``/pph/notch_frequencies`` column.

    The run record's notch tones when they are as many as the columns (the nominal ones:
    the diagnostics' ``tones_hz`` moves with tracking and holds harmonics), else the
    estimates' medians; without the topic, the notch's tones.
    """
    estimate = signals.frequencies.get(NOTCH_FREQUENCIES_TOPIC)
    if estimate is None:
        return list(controlled)
    columns = estimate[1].shape[1]
    rec = signals.record
    if rec is not None and len(rec.notch_tones_hz) == columns:
        return [float(f) for f in rec.notch_tones_hz]
    return [round(float(np.nanmedian(estimate[1][:, k])), 6) for k in range(columns)]


def tone_tracks(signals: BagSignals, controlled: list[float]
                ) -> list[tuple[str, np.ndarray, np.ndarray] | None]:
    """Per controlled tone: (source topic, message samples, Hz) of the track that follows it.

    The driver's true frequency (the column nearest the controller's estimate, or the
    nominal tone without one) when recorded, else the controller's estimate; None if neither.
    """
    truth = signals.frequencies.get(DISTURBANCE_FREQUENCIES_TOPIC)
    estimate = signals.frequencies.get(NOTCH_FREQUENCIES_TOPIC)
    targets = list(controlled)
    if estimate is not None and estimate[1].shape[1] == len(controlled):
        targets = [float(np.nanmedian(estimate[1][:, k])) for k in range(len(controlled))]
    else:
        estimate = None
    columns = moving_tones.match_columns(truth[1], targets) if truth is not None else \
        [None] * len(controlled)
    tracks: list[tuple[str, np.ndarray, np.ndarray] | None] = []
    for k, column in enumerate(columns):
        if column is not None:
            tracks.append((DISTURBANCE_FREQUENCIES_TOPIC, truth[0], truth[1][:, column]))
        elif estimate is not None:
            tracks.append((NOTCH_FREQUENCIES_TOPIC, estimate[0], estimate[1][:, k]))
        else:
            tracks.append(None)
    return tracks


def following_tones(signals: BagSignals, windows: dict[str, slice],
                    controlled: list[float]) -> list[dict[str, Any]]:
    """report.json's ``following_tones``: each controlled tone's level in a band following it.

    The level is :func:`tone_levels` of the z acceleration dechirped along the tone's
    recorded track (:func:`~hexapod_vibration.analysis.moving_tones.dechirp`), per window;
    ``frequency_span_hz`` is the track's range over the window. Empty when no frequency
    topic was recorded.
    """
    z, index = signals.z, signals.accel.sample_index
    rows = []
    for nominal, track in zip(controlled, tone_tracks(signals, controlled), strict=True):
        if track is None:
            continue
        topic, at, hz = track
        row: dict[str, Any] = {"frequency_hz": float(nominal), "source": topic}
        spans, floors = {}, {}
        for name, window in windows.items():
            track_hz = moving_tones.track_on_samples(at, hz, index[window])
            y, f_ref = moving_tones.dechirp(z[window], track_hz, FS)
            level, _, at_floor = tone_levels(y, [f_ref])
            row[f"{name}_db"] = round(level[0], 2)
            spans[name] = [round(float(track_hz.min()), 4), round(float(track_hz.max()), 4)]
            floors[name] = at_floor[0]
        if "controlled_db" in row:
            row["reduction_db"] = round(row["uncontrolled_db"] - row["controlled_db"], 2)
        row["frequency_span_hz"], row["at_noise_floor"] = spans, floors
        rows.append(row)
    return rows


def recorded_prediction(signals: BagSignals
                        ) -> tuple[int, str, np.ndarray, np.ndarray] | None:
    """(sample, view, frequency grid Hz, predicted |S| dB) of the last ``/pph/notch_sensitivity``.

    The view is its ``output_db`` row (the z axis) when given, else ``sigma_max_db``; None
    without a usable recorded prediction.
    """
    if not signals.sensitivity:
        return None
    sample, rows = signals.sensitivity[-1]
    view = "output_db" if "output_db" in rows else "sigma_max_db"
    if "frequency_hz" not in rows or view not in rows:
        return None
    return int(sample), view, rows["frequency_hz"], rows[view]


def prediction_difference(f: np.ndarray, measured_db: np.ndarray, grid_hz: np.ndarray,
                          predicted_db: np.ndarray, controlled: list[float],
                          lines: list[float], segment_s: float,
                          coherence: np.ndarray | None = None,
                          moved_hz: float = 0.0) -> dict[str, Any]:
    """Measured minus predicted |S| (dB) within 5 Hz of the controlled tones, lines left out.

    The prediction is the sensitivity of the tones at the fixed frequencies it was made
    for: when a notch oscillator ran more than one bin of the measured curve
    (``1 / segment_s``) from there over the compared windows (``moved_hz``,
    :func:`oscillators_moved_hz`: tracking a drift, a spin-up, a mismatch), nothing is
    compared (``near_tones_points`` 0, the differences None) and ``not_compared`` says why.

    Args:
        f: the measured curve's frequencies (Hz).
        measured_db: the measured |S| on ``f`` (dB).
        grid_hz: the prediction's frequencies (Hz).
        predicted_db: the predicted |S| on ``grid_hz`` (dB), interpolated onto ``f``.
        controlled: the notch's tones (Hz).
        lines: every other line left out (Hz).
        segment_s: the measured curve's Welch segment (s), for the lines' exclusion.
        coherence: the measurement's coherence on ``f``; when given, its least value over
            the compared bins is reported too (``near_tones_min_coherence``).
        moved_hz: the farthest (Hz) an oscillator ran from its tone in the prediction.
    """
    exclusion_hz = moving_tones.line_exclusion_hz(segment_s)
    near = moving_tones.near_tones_mask(f, controlled, lines, exclusion_hz)
    moved = moved_hz > 1.0 / segment_s
    if moved:
        near = np.zeros_like(near)
    difference = measured_db[near] - np.interp(f, grid_hz, predicted_db)[near]
    out = {"segment_s": _json_float(segment_s),
           "line_exclusion_hz": _json_float(exclusion_hz),
           "near_tones_points": int(np.count_nonzero(near)),
           "near_tones_max_difference_db": _json_float(
               float(np.max(np.abs(difference))) if near.any() else math.nan),
           "near_tones_rms_difference_db": _json_float(
               float(np.sqrt(np.mean(difference ** 2))) if near.any() else math.nan)}
    if coherence is not None:
        out["near_tones_min_coherence"] = (json_float(float(np.min(coherence[near])), 6)
                                           if near.any() else None)
    if moved:
        out["not_compared"] = (f"the notch ran up to {moved_hz:.2f} Hz from the tones the "
                               "prediction is for")
    return out


def oscillators_moved_hz(signals: BagSignals, configured: list[float],
                         samples: list[np.ndarray]) -> float:
    """The farthest (Hz) a notch oscillator ran from its configured tone on ``samples``.

    From the recorded ``/pph/notch_frequencies`` (one column per configured tone, where
    the prediction has the tones); 0 without it (the tones stayed where they were told).
    """
    estimate = signals.frequencies.get(NOTCH_FREQUENCIES_TOPIC)
    if estimate is None or estimate[1].shape[1] != len(configured):
        return 0.0
    at, table = estimate
    return max((float(np.max(np.abs(moving_tones.track_on_samples(at, table[:, k], rows) - f)))
                for rows in samples if rows.size for k, f in enumerate(configured)
                if np.any(np.isfinite(table[:, k]))), default=0.0)


def sensitivity_comparison(signals: BagSignals, windows: dict[str, slice],
                           controlled: list[float], lines: list[float], moved_hz: float = 0.0
                           ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """report.json's ``sensitivity`` and the curves of ``sensitivity.png``.

    Predicted: :func:`recorded_prediction`. Measured: the ratio of the controlled to the
    uncontrolled z spectrum (:func:`~hexapod_vibration.analysis.moving_tones.spectrum_ratio_db`).
    Their difference is summarised within 5 Hz of the controlled tones, outside every line's
    main lobe (:func:`prediction_difference`; not where a tone moved ``moved_hz``).
    Both empty without a recorded prediction or without a controlled window.
    """
    prediction = recorded_prediction(signals)
    if prediction is None or "controlled" not in windows:
        return {}, {}
    sample, view, grid, predicted = prediction
    z = signals.z
    on, off = z[windows["controlled"]], z[windows["uncontrolled"]]
    f, measured = moving_tones.spectrum_ratio_db(on, off, FS)
    segment_s = moving_tones.ratio_segment_s(on, off, FS)
    k = int(np.argmax(predicted))
    report = {"view": view.removesuffix("_db"), "prediction_sample": int(sample),
              "predicted_rise_db": _json_float(float(predicted[k])),
              "predicted_rise_at_hz": _json_float(float(grid[k])),
              **prediction_difference(f, measured, grid, predicted, controlled, lines,
                                      segment_s, moved_hz=moved_hz)}
    curves = {"frequency_hz": grid, "predicted_db": predicted, "measured_frequency_hz": f,
              "measured_db": measured}
    return report, curves


def levels_over_time(z: np.ndarray, index: np.ndarray, on: int | None, tones: list[float],
                      controlled: list[float]) -> dict[float, dict[str, Any]]:
    """Tone levels over time from ``CONVERGENCE_LEAD_S`` before control-on (one definition)."""
    if on is None or on <= int(index[0]) or on > int(index[-1]):
        return {}
    lines = sorted(set(tones) | set(controlled))
    out = {}
    for f in tones:
        lead = CONVERGENCE_LEAD_S + 0.5 * spectrum.level_window_s(f, lines)
        first = int(np.searchsorted(index, on - int(round(lead * FS))))
        out[f] = spectrum.tone_convergence(z[first:], FS, f, on, other_hz=lines,
                                           index=index[first:])
    return out


def convergence_s(over_time: dict[float, dict[str, Any]], controlled: list[float]) -> float:
    """report.json's ``convergence_s``: the slowest controlled tone's (NaN if one never settles).

    Args:
        over_time: :func:`levels_over_time` of the run.
        controlled: the notch's tones (Hz).
    """
    conv = [over_time[f]["convergence_s"] for f in over_time
            if any(abs(f - c) < 1e-6 for c in controlled)]
    return max(conv) if conv and all(map(math.isfinite, conv)) else math.nan


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
    ``/pph/accel`` in the bag to the driver's own count.
    """
    accel, st = signals.accel, signals.driver_status
    run = signals.run_samples()
    missing = accel.missing_in(run)
    if st:
        return {"mode": st.get("mode", "unknown"),
                "samples": run,
                "missed_samples": int(st.get("missed_samples", 0)) + missing,
                "rate_hz": _json_float(float(st.get("rate_hz", "nan"))),
                **{k: _json_float(float(st.get(k, "nan"))) for k in LOOP_KEYS}}
    stamps = accel.timestamp_ns
    span_s = (stamps[-1] - stamps[0]) * 1e-9 if stamps.size > 1 else 0.0
    latency = _bag_latency_ms(signals)
    return {"mode": "unknown", "samples": run, "missed_samples": missing,
            "rate_hz": _json_float((stamps.size - 1) / span_s if span_s > 0 else math.nan),
            "latency_ms_p50": _json_float(np.percentile(latency, 50) if latency.size else
                                          math.nan),
            "latency_ms_p99": _json_float(np.percentile(latency, 99) if latency.size else
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


REPORT_DIGITS = 6
"""Decimals of the numbers in report.json and details.json."""


def _json_float(value: float) -> float | None:
    return json_float(value, REPORT_DIGITS)


def _jsonable(value: Any) -> Any:
    return jsonable(value, REPORT_DIGITS)


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON (NaN written as null), numbers to 6 decimals, atomically."""
    write_json_values(path, data, REPORT_DIGITS)


# ---------------------------------------------------------------------------- tables
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
                 f"{loop['samples']} samples, {loop['missed_samples']} missed, "
                 f"{'-' if rate is None else f'{rate:.0f}'} samples/s")
    return "\n".join(lines)


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


# ---------------------------------------------------------------------------- entry point
def analyze_bag(bag_path: str | Path, out_dir: str | Path, model: ModelConfig,
                request: Request = Request(), control_on_s: float | None = None,
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
    result = analyze_signals(signals, request)
    if twin_signals is not None:
        from hexapod_vibration.analysis import twin

        result.report["twin"] = twin.compare(signals, twin_signals, result,
                                             twin_segment_s or twin.DEFAULT_SEGMENT_S)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "report.json", result.report)
    if plots:
        from hexapod_vibration.analysis import plots as plotting
        result.details["plots"] = [p.name for p in plotting.write_all(out, signals, result)]
    write_json(out / "details.json", result.details)
    return result
