"""Bounds of mu for a sweep point, to lay over the measured maps.

- ``mu_bound_identified``: the bound the notch supervisor enforces, from what the run
  identified (``LoopRecord.mu_bound``): a ``mu`` at or above it is clamped to half of it.
  ``mu_bound_method`` says which: ``eq. 18`` (the averaged bound of the tone
  identification's G at the tones) or ``Nyquist on G(f)`` (the Nyquist test of the loop on
  the broadband identification's G(f), with the canceller's update low-pass).
- ``mu_bound_model``: the largest ``mu`` at which the loop is stable on the **linear
  plant's model** (:func:`hexapod_vibration.sweep.loop_model.canceller_plant` of the
  point's model: the linear PPH with its pointing loop, anti-aliasing filter and DC
  blocker; not an identified model), with the coefficients the run installed and the
  canceller's update as it ran (the update low-pass ``update_lowpass_hz`` included): the
  Nyquist test of :func:`~hexapod_vibration.core.control.sensitivity.stable_mu_limit` on
  the model's exact frequency response. On the nonlinear PPH this is the linearisation
  about the preloaded joints, valid while the control forces do not unload them. None for
  moving tones (their type-2 update is not in that test).
- ``mu_limit_sensitivity``: the largest mu whose predicted sensitivity keeps the rise
  outside the tones within ``max_rise_db``. None: :func:`predicted_sensitivity_mu_limit`
  is the hook.

The model's bounds are cached per (plant, tones, coefficients, update) within a process:
the points of a mu axis share their identification (with common seeds), so a worker
computes each once.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from hexapod_vibration.core.control import sensitivity
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.sim.closed_loop import LoopRecord
from hexapod_vibration.core.sim.scenario import Scenario, notch_config
from hexapod_vibration.parameter_specs import moving_tones, update_lowpass_corner_hz
from hexapod_vibration.sweep.loop_model import canceller_plant, response_function

# The notch accepts mu in [0, 1): the model's bound is searched up to 1.
MODEL_MU_MAX = 1.0
PLANT_CACHE_SIZE = 32          # models kept per process (about 0.2 MB each)
BOUND_COLUMNS = ("mu_bound_identified", "mu_bound_model", "mu_limit_sensitivity")
METHODS = {"tones": "eq. 18", "broadband": "Nyquist on G(f)"}


def predicted_bounds(record: LoopRecord, scenario: Scenario, config: ModelConfig
                     ) -> dict[str, Any]:
    """The bounds of a run (None where a bound is not available) and the method."""
    out: dict[str, Any] = dict.fromkeys(BOUND_COLUMNS)
    notch = notch_config(scenario)
    out["mu_bound_method"] = METHODS.get(notch.identification, notch.identification)
    if record.coefficients is None:
        return out
    if math.isfinite(record.mu_bound):
        out["mu_bound_identified"] = float(record.mu_bound)
    if not moving_tones(vars(notch)):
        tones = tuple(float(f) for f in scenario.notch.tone_frequencies_hz)
        out["mu_bound_model"] = model_bound(config, tones, np.asarray(record.coefficients),
                                            update_lowpass_corner_hz(vars(notch)))
    out["mu_limit_sensitivity"] = predicted_sensitivity_mu_limit(record, scenario, config)
    return out


def model_bound(config: ModelConfig, tones_hz: tuple[float, ...], coefficients: np.ndarray,
                update_lowpass_hz: float) -> float:
    """The largest stable common mu of the canceller on the linear plant's model."""
    plant_key = _digest(config)
    key = _digest(config, tones_hz, coefficients, update_lowpass_hz)
    if key not in _BOUNDS:
        if plant_key not in _PLANTS:
            if len(_PLANTS) >= PLANT_CACHE_SIZE:
                _PLANTS.clear()
            fs = config.simulation.sample_rate_hz
            _PLANTS[plant_key] = response_function(canceller_plant(config), fs)
        _BOUNDS[key] = float(sensitivity.stable_mu_limit(
            _PLANTS[plant_key], tones_hz, config.simulation.sample_rate_hz, coefficients,
            mu_max=MODEL_MU_MAX, update_lowpass_hz=update_lowpass_hz))
    return _BOUNDS[key]


_PLANTS: dict[str, Callable[[np.ndarray], np.ndarray]] = {}
_BOUNDS: dict[str, float] = {}


def _digest(config: ModelConfig, *parts: Any) -> str:
    text = json.dumps(_plain(config), sort_keys=True, default=str)
    h = hashlib.sha256(text.encode())
    for part in parts:
        h.update(part.tobytes() if isinstance(part, np.ndarray) else repr(part).encode())
    return h.hexdigest()


def _plain(obj: Any) -> Any:
    fields = getattr(obj, "__dataclass_fields__", None)
    if fields is not None:
        return {name: _plain(getattr(obj, name)) for name in fields}
    return obj


def predicted_sensitivity_mu_limit(record: LoopRecord, scenario: Scenario,
                                   config: ModelConfig) -> float | None:
    """Hook: the largest mu whose predicted sensitivity rise stays within max_rise_db.

    Returns None (not computed in a sweep; the supervisor's own prediction for the rate
    it ran is the row's ``predicted_rise_db``); a value returned here is drawn on the maps.
    """
    return None
