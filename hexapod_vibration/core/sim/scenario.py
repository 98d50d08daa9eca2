"""Experiment scenarios (``config/scenarios/*.yaml``): shaker, plant, controllers, timeline.

A scenario says what the paper's experiment does, in SI units; the same file drives the
core-only closed loop (:mod:`hexapod_vibration.core.sim.closed_loop`) and the ROS experiment
runner. Timeline: the pointing loop holds its pose from t = 0, the notch controller
identifies the plant at its tones at ``identify_at_s`` (control still off), the
uncontrolled spectrum is taken over the ``window_s`` before ``control_on_s``, control goes
on at ``control_on_s``, and the controlled spectrum is taken over the last ``window_s``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.model.rotor import Rotor, rotor_or_none
from hexapod_vibration.core.model.shaker import ShakerTone, tones_from_arrays
from hexapod_vibration.parameter_specs import ADAPTATION_MODES, NOTCH_CONTROLLER
from hexapod_vibration.params_files import node_parameters
from hexapod_vibration.paths import share_directory


@dataclass(frozen=True)
class ShakerSettings:
    """Shaker tones (Hz, N peak, rad), slow drift (Hz peak, s period), noise (N RMS)."""

    frequencies_hz: tuple[float, ...] = ()
    amplitudes_n: tuple[float, ...] = ()
    phases_rad: tuple[float, ...] = ()
    drift_hz: float = 0.0
    drift_period_s: float = 60.0
    noise_rms_n: float = 0.0

    def tones(self) -> list[ShakerTone]:
        """The tones as :class:`ShakerTone` (validated)."""
        return tones_from_arrays(self.frequencies_hz, self.amplitudes_n, self.phases_rad,
                                 self.drift_hz, self.drift_period_s)


@dataclass(frozen=True)
class RotorSettings:
    """A rotating machine at the shaker's point: orders, N peak at Hz, profile.

    ``amplitudes_n`` are at ``reference_speed_hz`` and scale with the speed squared; the
    speed (Hz) is piecewise linear through (``profile_time_s``, ``profile_speed_hz``);
    ``tachometer`` publishes the speed on ``/pph/reference_frequency``. No orders: no rotor.
    """

    orders: tuple[float, ...] = ()
    amplitudes_n: tuple[float, ...] = ()
    reference_speed_hz: float = 50.0
    profile_time_s: tuple[float, ...] = (0.0,)
    profile_speed_hz: tuple[float, ...] = (50.0,)
    tachometer: bool = False

    def __post_init__(self) -> None:
        """Validate by building the rotor (ValueError with the reason)."""
        if not isinstance(self.tachometer, bool):
            raise ValueError(f"rotor.tachometer must be true or false, got {self.tachometer!r}")
        self.rotor()

    def rotor(self) -> Rotor | None:
        """The :class:`Rotor`, or None without orders."""
        return rotor_or_none(self.orders, self.amplitudes_n, self.reference_speed_hz,
                             self.profile_time_s, self.profile_speed_hz)


RUNNER_NOTCH_SETTINGS = frozenset({"enabled", "identify_delay_s"})
"""Notch settings the timeline sets (``control_on_s``, ``identify_at_s``), not the YAML."""
PRESETS_FOLDER = "presets"
"""Folder of ``config/`` holding the notch presets: ROS params files for notch_controller."""


def available_presets() -> list[str]:
    """Names of the notch presets (``config/presets/*.yaml`` without ``.yaml``)."""
    return sorted(p.stem for p in (share_directory() / "config" / PRESETS_FOLDER).glob("*.yaml"))


def notch_preset(name: str) -> dict[str, Any]:
    """The notch settings of preset ``name`` (``config/presets/<name>.yaml``, a params file).

    Raises:
        ValueError: an unknown preset (the reason lists the known ones), or a file that is
            not a params file of notch_controller's parameters.
    """
    presets = available_presets()
    if not isinstance(name, str) or name not in presets:
        raise ValueError(f"unknown preset {name!r}; presets: {', '.join(presets)}")
    path = share_directory() / "config" / PRESETS_FOLDER / f"{name}.yaml"
    values = node_parameters(path, NOTCH_CONTROLLER.node)
    if isinstance(values, str):
        raise ValueError(values)
    unknown = set(values) - set(NOTCH_CONTROLLER.names)
    if unknown:
        raise ValueError(f"{path}: not a notch_controller parameter: "
                         f"{', '.join(sorted(unknown))}")
    return values


@dataclass(frozen=True)
class NotchSettings:
    """Notch controller: tones (Hz), normalised rate mu (-), adaptation mode, the rest.

    ``settings`` holds any other notch parameter by its own name (``frequency_tracking``,
    ``harmonics``, ``mu_policy``, ...: the fields of
    :class:`~hexapod_vibration.core.control.notch_supervisor.NotchConfig`), checked there.
    In the YAML, ``preset: NAME`` starts from a preset's settings (:func:`notch_preset`,
    e.g. ``paper``: the paper's algorithm) and the section's own keys override them.
    """

    tone_frequencies_hz: tuple[float, ...] = ()
    mu: float = 0.002
    adaptation: str = "decentralized"
    settings: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_yaml(cls, values: dict[str, Any]) -> NotchSettings:
        """Split the YAML's ``notch:`` mapping; a name that is no notch setting raises."""
        values = _tuples(values)
        nested = values.pop("settings", None) or {}       # a dataclasses.asdict() round trip
        preset = values.pop("preset", None)
        try:
            base = _tuples(notch_preset(preset)) if preset is not None else {}
        except ValueError as exc:
            raise ValueError(f"notch: {exc}") from None
        values = {**base, **_tuples(nested), **values}
        own = {k: values.pop(k) for k in ("tone_frequencies_hz", "mu", "adaptation")
               if k in values}
        unknown = set(values) - set(NotchConfig.__dataclass_fields__)
        if unknown:
            raise ValueError(f"notch: not a notch parameter: {', '.join(sorted(unknown))}")
        timeline = set(values) & RUNNER_NOTCH_SETTINGS
        if timeline:
            raise ValueError(f"notch: {', '.join(sorted(timeline))} is set by the timeline "
                             "(identify_at_s, control_on_s)")
        try:
            NotchConfig().replaced(values)
        except ValueError as exc:
            raise ValueError(f"notch: {exc}") from None
        return cls(**own, settings=values)


@dataclass(frozen=True)
class TestSineSettings:
    """A sinusoid added to every actuator in phase (paper Fig. 4): Hz, N peak."""

    frequency_hz: float = 0.0
    amplitude_n: float = 0.0


@dataclass(frozen=True)
class Scenario:
    """One experiment of the paper on the simulated hexapod."""

    name: str
    description: str = ""
    seed: int = 1
    duration_s: float = 32.0
    control_on_s: float = 16.0
    identify_at_s: float = 1.0
    window_s: float = 10.0
    nonlinear: bool = True
    model_overrides: dict[str, Any] = field(default_factory=dict)
    shaker: ShakerSettings = ShakerSettings()
    rotor: RotorSettings = RotorSettings()
    notch: NotchSettings = NotchSettings()
    test_sine: TestSineSettings = TestSineSettings()
    target_pose: tuple[float, ...] = (0.0,) * 6
    report_tones_hz: tuple[float, ...] = ()
    report_harmonics_of_hz: float = 0.0

    def __post_init__(self) -> None:
        """Check the timeline and settings; ValueError with the field's name otherwise."""
        self.shaker.tones()
        if not (self.window_s > 0.0 and self.duration_s > 0.0):
            raise ValueError("window_s and duration_s must be > 0")
        if self.notch.adaptation not in ADAPTATION_MODES:
            raise ValueError(f"notch.adaptation must be one of {ADAPTATION_MODES}")
        if not np.isfinite(self.notch.mu) or self.notch.mu < 0.0:
            raise ValueError(f"notch.mu must be >= 0, got {self.notch.mu}")
        if len(self.target_pose) != 6:
            raise ValueError("target_pose must have 6 values [x, y, z (m), rx, ry, rz (rad)]")
        if self.notch.tone_frequencies_hz and not (
                self.control_on_s - self.window_s >= self.identify_at_s):
            raise ValueError("the uncontrolled window must start after identification begins")
        if self.control_on_s > self.duration_s:
            raise ValueError("control_on_s must not be after duration_s")
        if self.notch.tone_frequencies_hz:
            self._check_notch_settings()

    def _check_notch_settings(self) -> None:
        """The notch settings as a whole, as the controller will check them at start-up.

        A combination the controller refuses (e.g. a harmonic that the tracking range takes
        past fs/2, or ``reference_harmonics`` without one order per tone) is refused here,
        before a run brings anything up.
        """
        try:
            NotchSupervisor(notch_config(self))
        except (ValueError, KeyError) as exc:
            raise ValueError(f"notch: {exc}") from None

    def with_timeline(self, duration_s: float | None = None,
                      control_on_s: float | None = None) -> Scenario:
        """Copy with a different duration/control-on time (CLI overrides)."""
        values = dict(self.__dict__)
        if duration_s is not None:
            values["duration_s"] = float(duration_s)
        if control_on_s is not None:
            values["control_on_s"] = float(control_on_s)
        return Scenario(**values)

    @property
    def samples(self) -> int:
        """Samples in the run at 1 kHz."""
        return int(round(self.duration_s * 1000.0))


def notch_config(scenario: Scenario) -> NotchConfig:
    """The notch controller's settings for a scenario's run (what the runner gives the node).

    Control starts off (``enabled`` goes on at ``control_on_s``); the identification starts
    ``identify_at_s`` after the first sample.
    """
    notch = scenario.notch
    return NotchConfig().replaced({
        **notch.settings, "mu": notch.mu, "tone_frequencies_hz": notch.tone_frequencies_hz,
        "adaptation": notch.adaptation, "enabled": False,
        "identify_delay_s": scenario.identify_at_s})


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario YAML; unknown keys and bad values raise ValueError naming the file."""
    path = Path(path)
    with open(path, encoding="utf-8") as stream:
        data = yaml.safe_load(stream)
    try:
        return scenario_from_dict(data)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None


def scenario_from_dict(data: dict[str, Any]) -> Scenario:
    """Build a :class:`Scenario` from the YAML layout."""
    if not isinstance(data, dict) or "name" not in data:
        raise ValueError("a scenario is a mapping with at least a 'name'")
    values = dict(data)
    sections = {"shaker": ShakerSettings, "notch": NotchSettings.from_yaml,
                "test_sine": TestSineSettings, "rotor": RotorSettings}
    for key, make in sections.items():
        if key in values:
            section = values[key]
            values[key] = (make(section) if key == "notch" else make(**_tuples(section)))
    return Scenario(**_tuples(values))


def _tuples(values: dict[str, Any]) -> dict[str, Any]:
    if not isinstance(values, dict):
        raise ValueError(f"expected a mapping, got {values!r}")
    return {k: tuple(float(x) for x in v) if isinstance(v, list) else v
            for k, v in values.items()}
