"""The recorded prediction of the sensitivity |S(f)| against the one measured in the bag."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hexapod_vibration.analysis import moving_tones
from hexapod_vibration.analysis.bag_signals import FS, BagSignals
from hexapod_vibration.analysis.report_json import report_float
from hexapod_vibration.contract import NOTCH_FREQUENCIES_TOPIC
from hexapod_vibration.json_values import json_float


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
    out = {"segment_s": report_float(segment_s),
           "line_exclusion_hz": report_float(exclusion_hz),
           "near_tones_points": int(np.count_nonzero(near)),
           "near_tones_max_difference_db": report_float(
               float(np.max(np.abs(difference))) if near.any() else math.nan),
           "near_tones_rms_difference_db": report_float(
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
              "predicted_rise_db": report_float(float(predicted[k])),
              "predicted_rise_at_hz": report_float(float(grid[k])),
              **prediction_difference(f, measured, grid, predicted, controlled, lines,
                                      segment_s, moved_hz=moved_hz)}
    curves = {"frequency_hz": grid, "predicted_db": predicted, "measured_frequency_hz": f,
              "measured_db": measured}
    return report, curves
