"""Predicted bounds of mu for a sweep point, to lay over the measured maps.

- ``mu_bound_eq18``: the averaged bound of eq. 18 that the product enforces,
  :func:`adaptation.mu_bound` of the plant response the run identified and the
  coefficients it installed, with the loop delay of the core loop (``LoopRecord.mu_bound``).
- ``mu_bound_exact_lti``: :func:`adaptation.exact_mu_bound`, the first mu at which the
  exact LTI closed loop (canceller as an LTI filter, no averaging) loses stability, for the
  same installed coefficients and tones, on the **linear plant's model**
  (:func:`hexapod_vibration.sweep.loop_model.canceller_plant` of the point's model: the
  linear PPH with its pointing loop, anti-aliasing filter and DC blocker; not an
  identified model). On the nonlinear PPH this is the linearisation about the preloaded
  joints, valid while the control forces do not unload them.
- ``mu_limit_sensitivity``: the largest mu whose predicted sensitivity keeps the rise
  outside the tones within ``max_rise_db`` (issue 12). None until that prediction exists:
  :func:`predicted_sensitivity_mu_limit` is the hook.

Exact bounds are cached per (plant, tones, coefficients) within a process: the points of
a mu axis share their identification (with common seeds), so a worker computes each once.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.sim.closed_loop import LoopRecord
from hexapod_vibration.core.sim.scenario import Scenario
from hexapod_vibration.sweep.loop_model import canceller_plant

# The notch accepts mu in [0, 1): the exact bound is searched up to 1.
EXACT_MU_MAX = 1.0
PLANT_CACHE_SIZE = 32          # models kept per process (about 0.2 MB each)
BOUND_COLUMNS = ("mu_bound_eq18", "mu_bound_exact_lti", "mu_limit_sensitivity")


def predicted_bounds(record: LoopRecord, scenario: Scenario, config: ModelConfig
                     ) -> dict[str, float | None]:
    """The three predicted bounds of a run (None where a bound is not available)."""
    out: dict[str, float | None] = dict.fromkeys(BOUND_COLUMNS)
    if record.coefficients is None:
        return out
    if math.isfinite(record.mu_bound):
        out["mu_bound_eq18"] = float(record.mu_bound)
    tones = tuple(float(f) for f in scenario.notch.tone_frequencies_hz)
    out["mu_bound_exact_lti"] = exact_lti_bound(config, tones, np.asarray(record.coefficients))
    out["mu_limit_sensitivity"] = predicted_sensitivity_mu_limit(record, scenario, config)
    return out


def exact_lti_bound(config: ModelConfig, tones_hz: tuple[float, ...],
                    coefficients: np.ndarray) -> float:
    """:func:`adaptation.exact_mu_bound` on the linear plant's model of ``config``."""
    plant_key = _digest(config)
    key = _digest(config, tones_hz, coefficients)
    if key not in _EXACT:
        if plant_key not in _PLANTS:
            if len(_PLANTS) >= PLANT_CACHE_SIZE:
                _PLANTS.clear()
            _PLANTS[plant_key] = canceller_plant(config)
        fs = config.simulation.sample_rate_hz
        _EXACT[key] = float(adaptation.exact_mu_bound(_PLANTS[plant_key], tones_hz, fs,
                                                      coefficients, mu_max=EXACT_MU_MAX))
    return _EXACT[key]


_PLANTS: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
_EXACT: dict[str, float] = {}


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

    Returns None until the predicted-sensitivity work (issue 12) provides it; then it
    returns that limit for the run's identification and settings, and the maps draw it.
    """
    return None


def supervisor_backed_off(record: LoopRecord) -> bool | None:
    """Whether the loop's supervisor backed off during the run; None if it has none.

    Reads ``LoopRecord.backed_off`` once the core loop runs the notch supervisor.
    """
    value = getattr(record, "backed_off", None)
    return None if value is None else bool(value)
