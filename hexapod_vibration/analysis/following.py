"""Bands that follow the tones: the notch's tones, their recorded tracks, their levels.

A controlled tone that moves (a drift, a spin-up, tracking) is measured in a band following
its recorded track (:func:`~hexapod_vibration.analysis.moving_tones.dechirp`): the driver's
true frequency when recorded, else the controller's estimate.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod_vibration.analysis import moving_tones
from hexapod_vibration.analysis.bag_signals import FS, BagSignals
from hexapod_vibration.analysis.levels import tone_levels
from hexapod_vibration.contract import DISTURBANCE_FREQUENCIES_TOPIC, NOTCH_FREQUENCIES_TOPIC

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
