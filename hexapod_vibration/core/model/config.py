"""The physical model's parameters: YAML -> validated, frozen dataclasses (SI units).

Every field name carries its unit. :func:`load_model_config` reads ``config/pph_model.yaml``
(or any file with the same layout); :func:`model_config_from_dict` accepts overrides so a
scenario can change a few values (``{"strut": {"joint_free_play_m": 0.0}}``).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from hexapod_vibration.core.model.geometry import CubicHexapodGeometry


@dataclass(frozen=True)
class RigidBodyConfig:
    """A rigid body: mass (kg), principal inertia about its COM (kg m^2), COM offset (m)."""

    mass_kg: float
    inertia_kg_m2: tuple[float, float, float]
    com_offset_m: tuple[float, float, float]


@dataclass(frozen=True)
class StrutConfig:
    """One voice-coil strut: moving mass, suspension, stops, force constant, joints, limits."""

    moving_mass_kg: float
    suspension_stiffness_n_per_m: float
    suspension_damping_n_s_per_m: float
    stroke_limit_m: float
    hard_stop_stiffness_n_per_m: float
    hard_stop_damping_n_s_per_m: float
    force_constant_linear_per_stroke: float
    force_constant_quadratic_per_stroke: float
    joint_stiffness_n_per_m: float
    joint_damping_n_s_per_m: float
    joint_free_play_m: float
    force_limit_dynamic_n: float
    force_limit_static_n: float


@dataclass(frozen=True)
class MountConfig:
    """Passive isolation mounts between the bottom plate and the floating (inertial) table."""

    count: int
    radius_m: float
    height_m: float
    vertical_stiffness_n_per_m: float
    lateral_stiffness_n_per_m: float
    vertical_damping_n_s_per_m: float
    lateral_damping_n_s_per_m: float


SHAKER_BODIES = ("bottom_plate", "top_plate")


@dataclass(frozen=True)
class ShakerMountConfig:
    """Where the shaker pushes: on which body, at which point (m, from the cube centre).

    ``mounted_on`` is ``"bottom_plate"`` (the paper's bracket under the base: the
    disturbance comes through the struts) or ``"top_plate"`` (the paper's second shaker on
    top of the platform, or a payload's own cryocooler: the struts must react it). Force
    along z, limited to ``force_limit_n`` (N).
    """

    position_m: tuple[float, float, float]
    force_limit_n: float
    mounted_on: str = "bottom_plate"

    def __post_init__(self) -> None:
        """Check ``mounted_on``."""
        if self.mounted_on not in SHAKER_BODIES:
            raise ValueError(f"shaker.mounted_on must be one of {SHAKER_BODIES}, "
                             f"got {self.mounted_on!r}")


@dataclass(frozen=True)
class AccelerometerConfig:
    """In-line accelerometers: range (g), ADC bits, noise (g/sqrt(Hz)), anti-alias filter."""

    range_g: float
    bits: int
    noise_density_g_per_sqrt_hz: float
    antialias_cutoff_hz: float
    antialias_order: int


@dataclass(frozen=True)
class EddyConfig:
    """Eddy-current gap sensors: radius of the three pairs (m) and noise (m RMS)."""

    radius_m: float
    noise_rms_m: float


@dataclass(frozen=True)
class SimulationConfig:
    """Integration rate (Hz), published sample rate (Hz) and gravity (m/s^2)."""

    internal_rate_hz: float
    sample_rate_hz: float
    gravity_m_s2: float

    @property
    def substeps(self) -> int:
        """Internal steps per published sample."""
        return int(round(self.internal_rate_hz / self.sample_rate_hz))


@dataclass(frozen=True)
class ModelConfig:
    """The whole physical model of the simulated PPH."""

    geometry: CubicHexapodGeometry
    top_plate: RigidBodyConfig
    bottom_plate: RigidBodyConfig
    strut: StrutConfig
    mounts: MountConfig
    shaker: ShakerMountConfig
    accelerometer: AccelerometerConfig
    eddy: EddyConfig
    simulation: SimulationConfig

    def linear(self) -> ModelConfig:
        """The linear reference plant: no free-play and a constant force constant."""
        strut = _replace(self.strut, joint_free_play_m=0.0, force_constant_linear_per_stroke=0.0,
                         force_constant_quadratic_per_stroke=0.0)
        return _replace(self, strut=strut)


def _replace(obj: Any, **changes: Any) -> Any:
    values = {f.name: getattr(obj, f.name) for f in fields(obj) if f.init}
    values.update(changes)
    return type(obj)(**values)


_SECTIONS: dict[str, type] = {
    "geometry": CubicHexapodGeometry,
    "top_plate": RigidBodyConfig,
    "bottom_plate": RigidBodyConfig,
    "strut": StrutConfig,
    "mounts": MountConfig,
    "shaker": ShakerMountConfig,
    "accelerometer": AccelerometerConfig,
    "eddy": EddyConfig,
    "simulation": SimulationConfig,
}

_SIGNED = {"com_offset_m", "height_m", "position_m", "force_constant_linear_per_stroke"}
_NON_NEGATIVE = {"joint_free_play_m", "force_constant_quadratic_per_stroke",
                 "noise_density_g_per_sqrt_hz", "noise_rms_m"}


def load_model_config(path: str | Path, overrides: dict[str, Any] | None = None) -> ModelConfig:
    """Read a model YAML (layout of ``config/pph_model.yaml``) and apply nested ``overrides``."""
    path = Path(path)
    with open(path, encoding="utf-8") as stream:
        data = yaml.safe_load(stream)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping of sections, got {type(data).__name__}")
    return model_config_from_dict(data, overrides, source=str(path))


def model_config_from_dict(data: dict[str, Any], overrides: dict[str, Any] | None = None,
                           source: str = "model") -> ModelConfig:
    """Build a :class:`ModelConfig` from nested dicts, validating every value."""
    merged = merged_model_mapping(data, overrides, source)
    sections = {}
    for name, cls in _SECTIONS.items():
        if name not in merged:
            raise ValueError(f"{source}: missing section '{name}'")
        sections[name] = _build_section(cls, merged[name], f"{source}:{name}")
    unknown = set(merged) - set(_SECTIONS)
    if unknown:
        raise ValueError(f"{source}: unknown section(s) {sorted(unknown)}")
    config = ModelConfig(**sections)
    if config.simulation.internal_rate_hz % config.simulation.sample_rate_hz:
        raise ValueError(f"{source}: internal_rate_hz must be a multiple of sample_rate_hz")
    return config


def merged_model_mapping(data: dict[str, Any], overrides: dict[str, Any] | None = None,
                         source: str = "model") -> dict[str, Any]:
    """A copy of the model mapping ``data`` with nested ``overrides`` applied.

    Only keys the model has may be overridden (``ValueError`` names the first that is not).
    The values are checked when the mapping is built: :func:`model_config_from_dict`.
    """
    return _merge(copy.deepcopy(data), overrides or {}, source)


def _merge(base: dict[str, Any], overrides: dict[str, Any], source: str) -> dict[str, Any]:
    for key, value in overrides.items():
        if key not in base:
            raise ValueError(f"{source}: override of unknown key '{key}'")
        if isinstance(value, dict):
            if not isinstance(base[key], dict):
                raise ValueError(f"{source}: '{key}' is a value, not a section")
            _merge(base[key], value, source)
        else:
            base[key] = value
    return base


def _build_section(cls: type, values: Any, where: str) -> Any:
    if not isinstance(values, dict):
        raise ValueError(f"{where}: expected a mapping")
    names = {f.name for f in fields(cls) if f.init}
    required = names - _OPTIONAL
    missing, unknown = required - set(values), set(values) - names
    if missing or unknown:
        raise ValueError(f"{where}: missing {sorted(missing)}, unknown {sorted(unknown)}")
    clean = {key: _check_value(key, value, where) for key, value in values.items()}
    return cls(**clean)


_CHOICES = {"mounted_on": SHAKER_BODIES}
_OPTIONAL = {"mounted_on"}      # added later: older model files without it keep working


def _check_value(key: str, value: Any, where: str) -> Any:
    if key in _CHOICES:
        if value not in _CHOICES[key]:
            raise ValueError(f"{where}.{key}: expected one of {_CHOICES[key]}, got {value!r}")
        return value
    if isinstance(value, list):
        checked = tuple(_check_value(key, v, where) for v in value)
        if len(checked) != 3:
            raise ValueError(f"{where}.{key}: expected 3 values, got {len(checked)}")
        return checked
    if isinstance(value, str):   # PyYAML reads 3.0e4 (YAML 1.2 float) as a string
        try:
            value = float(value)
        except ValueError:
            raise ValueError(f"{where}.{key}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where}.{key}: expected a number, got {value!r}")
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError(f"{where}.{key}: must be finite, got {value!r}")
    if key in _NON_NEGATIVE and value < 0:
        raise ValueError(f"{where}.{key}: must be >= 0, got {value!r}")
    if key not in _SIGNED | _NON_NEGATIVE and value <= 0:
        raise ValueError(f"{where}.{key}: must be positive, got {value!r}")
    return int(value) if key in ("count", "bits", "antialias_order") else float(value)
