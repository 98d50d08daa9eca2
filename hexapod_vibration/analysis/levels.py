"""Tone levels of the top plate's z acceleration: in a window, and over time from control-on.

The level of a tone is ``20 log10(a_rms / 1 g)`` of its component in the z acceleration,
from a Blackman-Harris Welch spectrum (:mod:`hexapod_vibration.core.spectrum`). A tone below
the local noise floor is reported at the floor's level and flagged ``at_noise_floor``, so a
reduction is never larger than the floor lets us see.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hexapod_vibration.analysis.bag_signals import FS
from hexapod_vibration.core import spectrum

CONVERGENCE_LEAD_S = 2.0
"""Level-over-time curves start this long before control-on."""


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
