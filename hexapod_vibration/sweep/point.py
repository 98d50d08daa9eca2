"""One sweep point: the core closed loop (no ROS) and the metrics the report has.

:func:`run_point` is what a Dask worker calls. It never raises: a point that fails comes
back as a row with ``status = "failed"`` and its error, so it never stops a sweep. A point
that ran has the status of what control did (:mod:`hexapod_vibration.sweep.outcome`:
``ok``, ``clamped``, ``backed_off``, ``faded`` or ``refused``, the reason in
``control_note``). Every
point runs with one BLAS thread (``threadpoolctl``), in the client's process or in any
worker, so its numbers do not depend on where it ran.

The metrics come from the report's own definitions (:mod:`hexapod_vibration.analysis.report`
and :mod:`hexapod_vibration.core.spectrum`), on the top plate's z-axis acceleration
recovered from the six accelerometers, over the scenario's two windows (the ``window_s``
before control-on and the last ``window_s``):

- ``tones_*``: the report's tone rows (``analysis.levels.tone_levels``,
  ``analysis.report.tone_rows``) at ``report_tones_hz`` (else the notch tones): levels in
  dB re 1 g, reduction, floor flag.
- ``attenuation_db``: the smallest reduction among the *targeted lines*, the report tones
  within ``TARGET_RANGE_HZ`` of a notch tone (the lines the canceller is aimed at, also when
  it is told a slightly wrong frequency).
- ``band_*``: one-third-octave band levels of the continuous spectrum (the tone lines of
  the report, the notch and the shaker left out: :func:`spectrum.band_levels_db`).
- ``max_rise_db`` / ``max_rise_hz``: the largest rise elsewhere: the largest increase of
  a band, or of a report tone that is not targeted, from the uncontrolled to the
  controlled window (dB; where, Hz).
- ``max_rise_vs_off_db`` / ``max_rise_vs_off_hz`` (and ``band_off_db``): the same largest
  rise, measured against a reference run **without control** over the same controlled
  window: the same scenario and seed with no notch tones, so the same shaker and sensor
  noise sample for sample. The disturbance's own fluctuations cancel, which the
  before/after comparison cannot do (with 5 s windows its null level, control off, is
  2..8 dB in the 6-32 Hz bands, where lightly damped modes dominate); this is the
  "never worse than off" comparison. The reference is computed once per process for all
  points that share it (``seeds: common``).
- ``convergence_s``: :func:`convergence_s` of the targeted lines (the report's).
- ``diverged``: the loop went unstable: a non-finite value; or the canceller's command went
  past the actuator's dynamic rating in the controlled window (it asked for more than a
  strut can give; the weights then grow without bound); or the largest rise elsewhere is
  more than ``DIVERGED_RISE_DB`` (on the nonlinear PPH an unstable loop can settle into a
  limit cycle below the rating, the joints' free-play bounding it: measured 31 N and
  +69 dB at 316 Hz for mu = 0.015; stable settings rise by 10 dB at most).
- ``backed_off``: whether the divergence guard lowered mu during the run
  (:func:`~hexapod_vibration.sweep.outcome.control_outcome`, with ``mu_in_force`` and the
  per-tone rates ``tone_mu`` at the end of the run).
- ``peak_notch_command_n``, ``peak_actuator_force_n``: largest canceller command and
  applied force (N) after control-on; ``saturated_fraction`` of those samples with a
  command clipped at the dynamic rating.
- the bounds of mu: identified, and on the linear model (:mod:`hexapod_vibration.sweep.bounds`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import socket
import time
import traceback
import warnings
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from hexapod_vibration.analysis.levels import convergence_s, levels_over_time, tone_levels
from hexapod_vibration.analysis.report import tone_rows
from hexapod_vibration.contract import SAMPLE_RATE_HZ
from hexapod_vibration.core import spectrum
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.sim.closed_loop import CoreLoop, LoopRecord
from hexapod_vibration.core.sim.scenario import Scenario
from hexapod_vibration.sweep import bounds
from hexapod_vibration.sweep.grid import PointSpec, build_point
from hexapod_vibration.sweep.outcome import FAILED, control_outcome

TARGET_RANGE_HZ = 2.0       # a report tone this close to a notch tone is one it aims at
BAND_LOW_HZ, BAND_HIGH_HZ = 6.3, 400.0      # one-third-octave bands 6.3 .. 400 Hz
ERROR_CHARS = 500
DIVERGED_RISE_DB = 20.0


def run_point(spec: PointSpec) -> dict[str, Any]:
    """Run one point; its row of results (never raises)."""
    start = time.perf_counter()
    row: dict[str, Any] = {"point_id": spec.point_id, "index": spec.index,
                           "status": "ok", "error": None}
    try:
        with threadpool_limits(limits=1), warnings.catch_warnings():
            warnings.simplefilter("ignore", spectrum.ShortSignalWarning)
            scenario, config = build_point(spec.scenario, spec.model)
            loop = CoreLoop(config, scenario)
            record = loop.run()
            row.update(control_outcome(loop.notch, record, scenario.notch.mu))
            row.update(point_metrics(record, scenario, loop.config))
            row.update(rise_versus_off(record, scenario, config))
            row.update(bounds.predicted_bounds(record, scenario, config))
    except Exception as exc:  # noqa: BLE001 - a failing point is recorded, never fatal
        row.update(failed_row(spec, exc))
    row["elapsed_s"] = time.perf_counter() - start
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row


def failed_row(spec: PointSpec, exc: BaseException) -> dict[str, Any]:
    """The status and error of a point that failed with ``exc``, where it was raised."""
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {os.path.basename(frames[-1].filename)}:{frames[-1].lineno})" if frames else ""
    text = " ".join(f"{type(exc).__name__}: {exc}".split())
    return {"point_id": spec.point_id, "index": spec.index, "status": FAILED,
            "error": (text[:ERROR_CHARS] + where)}


def analysis_windows(record: LoopRecord, scenario: Scenario) -> tuple[slice, slice]:
    """Rows of the uncontrolled and controlled windows, as the report takes them."""
    n = record.accel_m_s2.shape[0]
    width = int(round(scenario.window_s * SAMPLE_RATE_HZ))
    on = record.control_on_sample
    if on - width < 0:
        raise ValueError(f"the uncontrolled window ({scenario.window_s:g} s) starts before "
                         "the run")
    return slice(on - width, on), slice(max(on, n - width), n)


def _lines(scenario: Scenario) -> tuple[list[float], list[float], list[float]]:
    """(report tones, notch tones, every line to leave out of the bands), Hz."""
    notch = [float(f) for f in scenario.notch.tone_frequencies_hz]
    tones = [float(f) for f in scenario.report_tones_hz] or notch
    shaker = [float(f) for f in scenario.shaker.frequencies_hz
              if 0.0 < f < 0.5 * SAMPLE_RATE_HZ]
    excluded = sorted({*tones, *notch, *shaker})
    return tones, notch, excluded


def point_metrics(record: LoopRecord, scenario: Scenario, config: ModelConfig
                  ) -> dict[str, Any]:
    """The report's metrics of one run (see the module docstring)."""
    z = config.geometry.platform_from_struts(record.accel_m_s2)[:, 2]
    before, after = analysis_windows(record, scenario)
    tones, notch, excluded = _lines(scenario)
    if not tones:
        raise ValueError("the scenario has no report_tones_hz and no notch tones")
    levels = {"uncontrolled": tone_levels(z[before], tones),
              "controlled": tone_levels(z[after], tones)}
    rows = tone_rows(tones, notch, levels)
    targeted = [f for f in tones if any(abs(f - c) <= TARGET_RANGE_HZ for c in notch)]
    reductions = [r["reduction_db"] for r in rows if r["frequency_hz"] in targeted]
    out: dict[str, Any] = {
        "tones_hz": tones,
        "tones_controlled": [r["controlled"] for r in rows],
        "tones_uncontrolled_db": [r["uncontrolled_db"] for r in rows],
        "tones_controlled_db": [r["controlled_db"] for r in rows],
        "tones_reduction_db": [r["reduction_db"] for r in rows],
        "tones_at_floor": list(levels["controlled"][2]),
        "attenuation_db": min(reductions) if reductions else None,
        "convergence_s": _finite(convergence_s(levels_over_time(
            z, np.arange(z.size), before.stop, tones, targeted), targeted))
        if targeted else None,
    }
    out.update(_rise(z, before, after, rows, targeted, excluded))
    out.update(_forces(record, config, before.stop, after))
    return out


def _bands() -> np.ndarray:
    return spectrum.third_octave_bands_hz(BAND_LOW_HZ, BAND_HIGH_HZ)


def _window_levels(z: np.ndarray, rows: slice, scenario: Scenario
                   ) -> tuple[np.ndarray, list[float]]:
    """(band levels, report-tone levels) of one window of the z-axis acceleration."""
    tones, _, excluded = _lines(scenario)
    bands = spectrum.band_levels_db(z[rows], SAMPLE_RATE_HZ, _bands(), excluded)
    return bands, tone_levels(z[rows], tones)[0]


_REFERENCES: dict[str, tuple[np.ndarray, list[float]]] = {}
REFERENCE_CACHE_SIZE = 64


def reference_scenario(scenario: Scenario) -> Scenario:
    """The same run without control: default notch settings and no tones.

    No identification either, so every point that differs only in its notch shares it.
    """
    return dataclasses.replace(scenario, notch=dataclasses.replace(type(scenario.notch)(),
                                                                   tone_frequencies_hz=()))


def _reference_levels(scenario: Scenario, config: ModelConfig, rows: slice
                      ) -> tuple[np.ndarray, list[float]]:
    reference = reference_scenario(scenario)
    text = json.dumps([dataclasses.asdict(reference), rows.start, rows.stop], sort_keys=True,
                      default=repr)
    key = hashlib.sha256(text.encode()).hexdigest()
    if key not in _REFERENCES:
        if len(_REFERENCES) >= REFERENCE_CACHE_SIZE:
            _REFERENCES.clear()
        loop = CoreLoop(config, reference)
        record = loop.run()
        z = loop.config.geometry.platform_from_struts(record.accel_m_s2)[:, 2]
        _REFERENCES[key] = _window_levels(z, rows, scenario)
    return _REFERENCES[key]


def rise_versus_off(record: LoopRecord, scenario: Scenario, config: ModelConfig
                    ) -> dict[str, Any]:
    """Largest rise of a band or an untargeted line over the run without control."""
    _, after = analysis_windows(record, scenario)
    z = config.geometry.platform_from_struts(record.accel_m_s2)[:, 2]
    bands_on, tones_on = _window_levels(z, after, scenario)
    bands_off, tones_off = _reference_levels(scenario, config, after)
    tones, notch, _ = _lines(scenario)
    targeted = {f for f in tones if any(abs(f - c) <= TARGET_RANGE_HZ for c in notch)}
    candidates = [(float(on - off), float(f)) for f, on, off in
                  zip(_bands()[:, 0], bands_on, bands_off, strict=True)
                  if np.isfinite(on) and np.isfinite(off)]
    candidates += [(float(on - off), f) for f, on, off in zip(tones, tones_on, tones_off,
                                                              strict=True) if f not in targeted]
    rise, where = max(candidates, default=(math.nan, math.nan))
    diverged = rise > DIVERGED_RISE_DB
    return {"band_off_db": [_finite(v) for v in bands_off],
            "max_rise_vs_off_db": _finite(rise), "max_rise_vs_off_hz": _finite(where),
            **({"diverged": True} if diverged else {})}


def _rise(z: np.ndarray, before: slice, after: slice, rows: list[dict], targeted: list[float],
          excluded: list[float]) -> dict[str, Any]:
    """Band levels and the largest rise outside the targeted lines."""
    bands = _bands()
    unc = spectrum.band_levels_db(z[before], SAMPLE_RATE_HZ, bands, excluded)
    ctl = spectrum.band_levels_db(z[after], SAMPLE_RATE_HZ, bands, excluded)
    candidates = [(float(c - u), float(f)) for f, u, c in zip(bands[:, 0], unc, ctl,
                                                              strict=True)
                  if np.isfinite(u) and np.isfinite(c)]
    band_rise = max(candidates, default=(math.nan, math.nan))
    candidates += [(-r["reduction_db"], r["frequency_hz"]) for r in rows
                   if r["frequency_hz"] not in targeted]
    rise, where = max(candidates, default=(math.nan, math.nan))
    return {"band_centre_hz": [float(f) for f in bands[:, 0]],
            "band_uncontrolled_db": [_finite(v) for v in unc],
            "band_controlled_db": [_finite(v) for v in ctl],
            "max_band_rise_db": _finite(band_rise[0]), "max_band_rise_hz": _finite(band_rise[1]),
            "max_rise_db": _finite(rise), "max_rise_hz": _finite(where)}


def _forces(record: LoopRecord, config: ModelConfig, on: int, after: slice) -> dict[str, Any]:
    """Peak command and force after control-on, saturation, and the divergence flag."""
    limit = config.strut.force_limit_dynamic_n
    command = record.notch_command_n[on:]
    applied = record.actuator_force_n[on:]
    finite = bool(np.all(np.isfinite(record.accel_m_s2)) and np.all(np.isfinite(command)))
    over = np.abs(command) >= limit
    wound_up = bool(np.any(over[after.start - on:]))
    return {"peak_notch_command_n": _finite(np.max(np.abs(command), initial=0.0)),
            "peak_actuator_force_n": _finite(np.max(np.abs(applied), initial=0.0)),
            "saturated_fraction": float(np.mean(np.any(over, axis=1))) if command.size else 0.0,
            "diverged": (not finite) or wound_up}


def _finite(value: Any) -> float | None:
    """A float, or None for NaN/inf (a null in the table)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None
