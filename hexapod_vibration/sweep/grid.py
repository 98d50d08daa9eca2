"""Sweep grids (``config/sweeps/*.yaml``): a base scenario, the values to sweep, the maps.

A grid names a base scenario and assigns values to **dotted paths** into the scenario's
mapping, the way its YAML is written: ``notch.mu``, ``shaker.frequencies_hz[0]``,
``model_overrides.top_plate.mass_kg``, ``seed``. Every field of the scenario (with its
defaults filled in) can be addressed, and so can every value of the physical model under
``model_overrides.`` (the packaged ``pph_model.yaml``, or the grid's ``model_file``), and
every notch setting under ``notch.settings.`` (``notch.settings.identification``,
``notch.settings.divergence_guard``: the base's value or the controller's default). A
field added to :class:`~hexapod_vibration.core.sim.scenario.Scenario` or
:class:`~hexapod_vibration.core.control.notch_supervisor.NotchConfig` is addressable
without any change here.

Layout::

    name: mu_bound                      # used in titles and file names
    description: "..."
    base_scenario: single_tone_harmonic # a name in config/scenarios/ or a YAML path
    model_file: pph_model.yaml          # optional: config/<file> or a path
    set:                                # optional: changes to the base, before the axes
      duration_s: 22.0
      notch.tone_frequencies_hz: [40.0]
    axes:                               # optional: the product of every axis' values
      notch.adaptation: [decentralized, centralized]
      notch.mu: {values: [0.001, 0.01, 0.1], scale: log, label: "mu (1/sample)"}
    points:                             # optional: a list of assignments, each crossed
      - {shaker.noise_rms_n: 0.0}       # with the product of the axes
    seeds: per_point                    # or common: the base scenario's seed everywhere
    plot: {x: notch.tone_frequencies_hz[0], y: notch.mu}

Seeds are deterministic: ``per_point`` derives each point's seed from the base seed and
the point's assignments (SHA-256), so a point keeps its seed when the grid grows;
``common`` gives every point the base seed (common random numbers: the maps then differ
from cell to cell by the swept values only). A ``seed`` axis overrides both.

:func:`load_grid` checks every path against the base scenario and builds every point's
scenario and model before any simulation runs, and refuses a point whose control-on or
analysis window falls inside the notch's identification
(:func:`~hexapod_vibration.core.sim.timeline.timeline_conflict`): a bad grid is a
:class:`GridError` with a one-line message.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import itertools
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hexapod_vibration.core.control.notch_supervisor import NotchConfig
from hexapod_vibration.core.model.config import ModelConfig, model_config_from_dict
from hexapod_vibration.core.sim.scenario import (
    RUNNER_NOTCH_SETTINGS,
    NotchSettings,
    Scenario,
    scenario_from_dict,
)
from hexapod_vibration.core.sim.timeline import timeline_conflict
from hexapod_vibration.paths import config_path, scenario_path

GRID_KEYS = {"name", "description", "base_scenario", "model_file", "set", "axes", "points",
             "seeds", "plot"}
AXIS_KEYS = {"values", "label", "scale"}
SEED_MODES = ("per_point", "common")
SCALES = ("linear", "log")
MODEL_KEY = "model_overrides"
# Bump when the metrics of a point change meaning: results of an older version are then
# not taken as done by a resumed sweep.
METRICS_VERSION = 2
_PART = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)((?:\[-?\d+\])*)$")
_INDEX = re.compile(r"\[(-?\d+)\]")


class GridError(ValueError):
    """A grid that cannot be run; the message is one line naming the file and the cause."""


# ----------------------------------------------------------------------------- paths
def parse_path(path: str) -> list[str | int]:
    """``"shaker.frequencies_hz[0]"`` -> ``["shaker", "frequencies_hz", 0]``."""
    if not isinstance(path, str) or not path:
        raise GridError(f"a path must be a non-empty string, got {path!r}")
    keys: list[str | int] = []
    for part in path.split("."):
        match = _PART.match(part)
        if match is None:
            raise GridError(f"{path!r}: malformed path element {part!r}")
        keys.append(match.group(1))
        keys.extend(int(i) for i in _INDEX.findall(match.group(2)))
    return keys


def get_path(mapping: Any, path: str) -> Any:
    """The value at ``path``; GridError naming the first element that does not resolve."""
    node = mapping
    walked = ""
    for key in parse_path(path):
        where = walked or "the scenario"
        if isinstance(key, int):
            if not isinstance(node, (list, tuple)):
                raise GridError(f"{path!r}: {where} is not a list")
            if not -len(node) <= key < len(node):
                raise GridError(f"{path!r}: index {key} out of range ({where} has "
                                f"{len(node)} values)")
            node, walked = node[key], f"{walked}[{key}]"
        else:
            if node is None:
                raise GridError(f"{path!r}: {where} is null in the base scenario (give the "
                                "base a value there first)")
            if not isinstance(node, dict):
                raise GridError(f"{path!r}: {where} is a value, not a section")
            if key not in node:
                known = ", ".join(sorted(node)) or "none"
                raise GridError(f"{path!r}: no field {key!r} in {where} (fields: {known})")
            node, walked = node[key], f"{walked}.{key}" if walked else key
    return node


def set_path(mapping: dict, path: str, value: Any) -> None:
    """Replace the value at ``path`` (which must exist) by ``value``, type-checked."""
    keys = parse_path(path)
    parent_path = _join(keys[:-1])
    parent = get_path(mapping, parent_path) if parent_path else mapping
    last = keys[-1]
    if isinstance(last, int):
        if not isinstance(parent, (list, tuple)):
            raise GridError(f"{path!r}: {parent_path} is not a list")
        get_path(mapping, path)
        if isinstance(parent, tuple):        # tuples of dataclasses.asdict: make mutable
            set_path(mapping, parent_path, list(parent))
            parent = get_path(mapping, parent_path)
        _check_type(path, parent[last], value)
        parent[last] = value
    else:
        old = get_path(mapping, path)
        _check_type(path, old, value)
        parent[last] = copy.deepcopy(value)


def _join(keys: list[str | int]) -> str:
    text = ""
    for key in keys:
        text += f"[{key}]" if isinstance(key, int) else (f".{key}" if text else key)
    return text


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, float)):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, (list, tuple)):
        return "list"
    if isinstance(value, dict):
        return "mapping"
    return type(value).__name__


def _check_type(path: str, old: Any, new: Any) -> None:
    """A value replaces one of the same kind (number, bool, string, list, mapping)."""
    old_kind, new_kind = _kind(old), _kind(new)
    if old_kind not in ("null", new_kind):
        raise GridError(f"{path!r}: expected a {old_kind} like the base's {old!r}, got "
                        f"{new!r}")


# ----------------------------------------------------------------------------- grid
@dataclass(frozen=True)
class Axis:
    """One swept path, its values, how to label and scale it on a map."""

    path: str
    values: tuple[Any, ...]
    label: str = ""
    scale: str = "linear"

    @property
    def title(self) -> str:
        """The axis label, or its path."""
        return self.label or self.path


@dataclass(frozen=True)
class PointSpec:
    """Everything a worker needs to run one point (plain data, picklable).

    ``scenario`` is the complete scenario mapping (defaults filled in) whose
    ``model_overrides`` hold the complete model mapping; ``assignments`` the values of the
    swept paths (and ``seed``).
    """

    point_id: str
    index: int
    assignments: dict[str, Any]
    scenario: dict[str, Any]
    model: dict[str, Any]


@dataclass
class Grid:
    """A loaded, validated grid."""

    name: str
    description: str
    source: Path
    base_scenario: str
    axes: list[Axis]
    point_sets: list[dict[str, Any]]
    seeds: str
    plot: dict[str, Any]
    points: list[PointSpec] = field(default_factory=list)
    raw: dict[str, Any] = field(default_factory=dict)

    def axis(self, path: str) -> Axis | None:
        """The axis of ``path``, or None."""
        return next((a for a in self.axes if a.path == path), None)

    @property
    def swept_paths(self) -> list[str]:
        """Every path a point assigns (axes first, then those of ``points``)."""
        paths = [a.path for a in self.axes]
        for assignment in self.point_sets:
            paths += [p for p in assignment if p not in paths]
        return paths


def load_grid(path: str | Path) -> Grid:
    """Read and validate a grid YAML, building every point; GridError (one line) if bad."""
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as stream:
            raw = yaml.safe_load(stream)
    except OSError as exc:
        raise GridError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None)
        raise GridError(f"{path}: not valid YAML{where}" + (f": {problem}" if problem else "")
                        + " (quote paths with [i] inside {...} or [...])") from None
    try:
        return grid_from_dict(raw, path)
    except GridError as exc:
        raise GridError(f"{path}: {exc}") from None


def grid_from_dict(raw: Any, source: Path) -> Grid:
    """Build a :class:`Grid` from the YAML mapping (see the module docstring)."""
    if not isinstance(raw, dict):
        raise GridError("a grid is a mapping with 'name', 'base_scenario' and 'axes' or "
                        "'points'")
    unknown = set(raw) - GRID_KEYS
    if unknown:
        raise GridError(f"unknown key(s) {sorted(unknown)} (known: {sorted(GRID_KEYS)})")
    for key in ("name", "base_scenario"):
        if not isinstance(raw.get(key), str) or not raw[key]:
            raise GridError(f"'{key}' must be a non-empty string")
    axes = _axes(raw.get("axes") or {})
    point_sets = _point_sets(raw.get("points") or [])
    if not axes and not point_sets:
        raise GridError("nothing to sweep: give 'axes' or 'points'")
    seeds = raw.get("seeds", "per_point")
    if seeds not in SEED_MODES:
        raise GridError(f"'seeds' must be one of {SEED_MODES}, got {seeds!r}")
    grid = Grid(name=raw["name"], description=str(raw.get("description", "")),
                source=source, base_scenario=raw["base_scenario"], axes=axes,
                point_sets=point_sets, seeds=seeds, plot=dict(raw.get("plot") or {}), raw=raw)
    base = _base_mapping(grid, raw.get("model_file"), source)
    for set_path_, value in _mapping(raw.get("set") or {}, "set").items():
        set_path(base, set_path_, value)
    grid.points = _build_points(grid, base)
    _check_plot(grid)
    return grid


def _mapping(value: Any, what: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise GridError(f"'{what}' must be a mapping of path: value")
    return value


def _axes(raw: Any) -> list[Axis]:
    axes = []
    for path, spec in _mapping(raw, "axes").items():
        parse_path(path)
        if isinstance(spec, dict):
            unknown = set(spec) - AXIS_KEYS
            if unknown:
                raise GridError(f"axis {path!r}: unknown key(s) {sorted(unknown)} (known: "
                                f"{sorted(AXIS_KEYS)})")
            values, label, scale = spec.get("values"), spec.get("label", ""), spec.get(
                "scale", "linear")
        else:
            values, label, scale = spec, "", "linear"
        if not isinstance(values, list) or not values:
            raise GridError(f"axis {path!r}: give a non-empty list of values")
        if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
            raise GridError(f"axis {path!r}: repeated values")
        if scale not in SCALES:
            raise GridError(f"axis {path!r}: scale must be one of {SCALES}, got {scale!r}")
        if scale == "log" and not all(_kind(v) == "number" and v > 0 for v in values):
            raise GridError(f"axis {path!r}: a log scale needs positive numbers")
        axes.append(Axis(path, tuple(values), str(label), scale))
    return axes


def _point_sets(raw: Any) -> list[dict[str, Any]]:
    if not isinstance(raw, list):
        raise GridError("'points' must be a list of mappings of path: value")
    sets = []
    for k, assignment in enumerate(raw):
        if not isinstance(assignment, dict) or not assignment:
            raise GridError(f"points[{k}] must be a non-empty mapping of path: value")
        for path in assignment:
            parse_path(path)
        sets.append(dict(assignment))
    return sets


def _check_plot(grid: Grid) -> None:
    unknown = set(grid.plot) - {"x", "y"}
    if unknown:
        raise GridError(f"plot: unknown key(s) {sorted(unknown)} (known: ['x', 'y'])")
    for key in ("x", "y"):
        if key in grid.plot and grid.axis(grid.plot[key]) is None:
            raise GridError(f"plot.{key} = {grid.plot[key]!r} is not one of the axes "
                            f"{[a.path for a in grid.axes]}")


def resolve_scenario(name: str, relative_to: Path) -> Path:
    """A scenario name in config/scenarios/, or a YAML path (absolute or beside the grid)."""
    if name.endswith((".yaml", ".yml")):
        candidate = Path(name)
        if not candidate.is_absolute():
            candidate = relative_to.parent / candidate
        if not candidate.is_file():
            raise GridError(f"base_scenario: no file {candidate}")
        return candidate
    try:
        return scenario_path(name)
    except FileNotFoundError as exc:
        raise GridError(f"base_scenario: {exc}") from None


def _read_yaml_mapping(path: Path, what: str) -> dict[str, Any]:
    try:
        with open(path, encoding="utf-8") as stream:
            data = yaml.safe_load(stream)
    except (OSError, yaml.YAMLError) as exc:
        raise GridError(f"{what}: cannot read {path}: {exc}") from None
    if not isinstance(data, dict):
        raise GridError(f"{what}: {path} is not a mapping")
    return data


def _model_file(name: Any, relative_to: Path) -> Path:
    if name is None:
        return config_path("pph_model.yaml")
    candidate = Path(str(name))
    if not candidate.is_absolute() and (relative_to.parent / candidate).is_file():
        return relative_to.parent / candidate
    if candidate.is_file():
        return candidate
    try:
        return config_path(str(name))
    except FileNotFoundError as exc:
        raise GridError(f"model_file: {exc}") from None


def _base_mapping(grid: Grid, model_file: Any, source: Path) -> dict[str, Any]:
    """The base scenario as a complete mapping, its model overrides the complete model."""
    scenario_file = resolve_scenario(grid.base_scenario, source)
    data = _read_yaml_mapping(scenario_file, "base_scenario")
    model = _read_yaml_mapping(_model_file(model_file, source), "model_file")
    try:
        scenario = scenario_from_dict(data)
        model_config_from_dict(model, scenario.model_overrides)
    except (TypeError, ValueError) as exc:
        raise GridError(f"base_scenario {scenario_file}: {exc}") from None
    full = dataclasses.asdict(scenario)
    full["notch"]["settings"] = _notch_settings(scenario.notch)
    full[MODEL_KEY] = _merged(model, scenario.model_overrides)
    grid.raw = {**grid.raw, "_model": model}
    return full


def _notch_settings(notch: NotchSettings) -> dict[str, Any]:
    """Every notch setting a scenario may give, the base's or else its default."""
    own = {f.name for f in dataclasses.fields(NotchSettings)} | RUNNER_NOTCH_SETTINGS
    defaults = {f.name: getattr(NotchConfig(), f.name) for f in dataclasses.fields(NotchConfig)
                if f.name not in own}
    return copy.deepcopy({**defaults, **notch.settings})


def _merged(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _assignments(grid: Grid) -> list[dict[str, Any]]:
    """Every point's assignments: each of ``points`` (or none) x the product of the axes."""
    combos = list(itertools.product(*(a.values for a in grid.axes))) if grid.axes else [()]
    sets = grid.point_sets or [{}]
    out = []
    for fixed in sets:
        for combo in combos:
            assignment = dict(fixed)
            for axis, value in zip(grid.axes, combo, strict=True):
                if axis.path in assignment:
                    raise GridError(f"{axis.path!r} is both an axis and in 'points'")
                assignment[axis.path] = value
            out.append(assignment)
    return out


def point_seed(base_seed: int, assignments: dict[str, Any]) -> int:
    """Deterministic seed in [0, 2^31) from the base seed and a point's assignments."""
    text = json.dumps({"base_seed": int(base_seed), "assignments": assignments},
                      sort_keys=True, default=str)
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "big") & 0x7FFFFFFF


def _build_points(grid: Grid, base: dict[str, Any]) -> list[PointSpec]:
    model_base = grid.raw["_model"]
    points, seen = [], {}
    for index, assignment in enumerate(_assignments(grid)):
        mapping = copy.deepcopy(base)
        for path, value in assignment.items():
            set_path(mapping, path, value)
        if "seed" not in assignment:
            mapping["seed"] = (int(base["seed"]) if grid.seeds == "common"
                               else point_seed(int(base["seed"]), assignment))
        assignments = {**assignment, "seed": mapping["seed"]}
        try:
            scenario, config = build_point(mapping, model_base)
            conflict = timeline_conflict(scenario, config.simulation.sample_rate_hz)
        except (TypeError, ValueError) as exc:
            conflict = " ".join(str(exc).split())
        if conflict is not None:
            raise GridError(f"point {index} {_describe(assignment)}: {conflict}")
        point_id = _point_id(mapping, model_base)
        if point_id in seen:
            raise GridError(f"points {seen[point_id]} and {index} are the same point")
        seen[point_id] = index
        points.append(PointSpec(point_id, index, assignments, mapping, model_base))
    return points


def _describe(assignment: dict[str, Any]) -> str:
    return "{" + ", ".join(f"{k}: {v!r}" for k, v in assignment.items()) + "}"


def _point_id(mapping: dict[str, Any], model: dict[str, Any]) -> str:
    text = json.dumps({"scenario": mapping, "model": model, "metrics": METRICS_VERSION},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def build_point(scenario: dict[str, Any], model: dict[str, Any]
                ) -> tuple[Scenario, ModelConfig]:
    """The :class:`Scenario` and :class:`ModelConfig` of a point's mappings."""
    built = scenario_from_dict(copy.deepcopy(scenario))
    return built, model_config_from_dict(model, built.model_overrides)
