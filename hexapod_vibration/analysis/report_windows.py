"""The report's spectrum windows: before and after control-on, gap-free, identification left out.

Spectrum windows never include the notch controller's plant identification (its test
tones): the identification interval comes from the notch's ``/diagnostics``, else from its
reported state, else from the run record. Missing samples are never interpolated: a window
is the longest gap-free run.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.analysis.bag_signals import FS, BagSignals

DEFAULT_WINDOW_S = 10.0
IDENTIFICATION_SETTLE_S = 0.5
"""Left out after an identification ends: the plant's response to its test tones rings down."""
MIN_BINS_PER_SPACING = 9
"""A spectrum separates two lines ``d`` Hz apart when it has at least 9 bins per ``d``
(main lobe 4 bins each side plus a half-bin offset and margin, see core.spectrum): a window
shorter than ``9 / d`` s cannot give the tone table."""


class WindowTooShort(ValueError):
    """A spectrum window whose usable (gap-free, identification-free) run is too short."""


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


def report_windows(signals: BagSignals, index: np.ndarray, window_s: float | None,
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
