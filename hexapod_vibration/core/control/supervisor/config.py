"""The notch controller's settings, generated from the parameter declarations.

:class:`NotchConfig` has one field per notch setting of
:data:`~hexapod_vibration.parameter_specs.NOTCH_CONTROLLER` (every parameter of the node but
the scheduling of its loop), with the declared default, and checks every value against its
declaration when it is built: ``parameter_specs`` is the one definition of the settings,
their defaults and ranges. The checks of settings that belong together (the node's joint
checks, e.g. ``frequency_tracking`` needs ``identification: broadband``) run there too;
what depends on the controller's state (tones x orders, the stability bound, the update
low-pass fixed at start-up) is checked by :mod:`.planning`.

:class:`Settings` holds the settings in force; the collaborators read what they need from
it when they need it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from hexapod_vibration.core.control.notch import FADE_S
from hexapod_vibration.parameter_specs import (
    LOOP_SCHEDULING,
    NOTCH_CONTROLLER,
    ParameterSpec,
    update_lowpass_corner_hz,
)

NOTCH_SETTINGS: tuple[ParameterSpec, ...] = tuple(
    spec for spec in NOTCH_CONTROLLER.parameters
    if spec.name not in {s.name for s in LOOP_SCHEDULING})
"""The declarations of the notch settings, in the node's order."""
_FIELD_TYPES = {"bool": bool, "int": int, "double": float, "string": str,
                "double[]": tuple[float, ...]}
"""The field's type for each declared parameter type (arrays are tuples: hashable)."""


def _field(spec: ParameterSpec) -> tuple[str, type, dataclasses.Field]:
    default = tuple(spec.default) if spec.is_array else spec.default
    return spec.name, _FIELD_TYPES[spec.type], dataclasses.field(default=default)


def _docstring() -> str:
    lines = ["Settings of the notch controller; the field names are the node's ROS parameters.",
             "", "Generated from ``parameter_specs.NOTCH_CONTROLLER``: each value is checked "
             "against its", "declaration, and the values together against the node's joint "
             "checks, when the", "settings are built (ValueError with the reason).", "",
             "Attributes:"]
    for spec in NOTCH_SETTINGS:
        unit = f" ({spec.unit})" if spec.unit else ""
        lines.append(f"    {spec.name}: {spec.description}{unit}.")
    return "\n".join(lines)


def _check(self: Any) -> None:
    """Refuse a value its declaration refuses, or values the joint checks refuse (the reason)."""
    for spec in NOTCH_SETTINGS:
        reason = spec.check(getattr(self, spec.name))
        if reason:
            raise ValueError(reason)
    reason = NOTCH_CONTROLLER.check_together(vars(self))
    if reason:
        raise ValueError(reason)


def _replaced(self: Any, changes: Mapping[str, Any]) -> Any:
    """A copy with ``changes`` (parameter name -> value), checked.

    Raises:
        KeyError: a name that is not a notch setting.
        ValueError: a value its declaration refuses (the reason).
    """
    unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
    if unknown:
        raise KeyError(f"not a notch setting: {', '.join(sorted(unknown))}")
    values = dict(changes)
    for name in ("tone_frequencies_hz", "reference_harmonics"):
        if name in values:
            try:
                values[name] = tuple(float(f) for f in values[name] or ())
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be an array of numbers, got "
                                 f"{values[name]!r}") from None
    return dataclasses.replace(self, **values)


NotchConfig = dataclasses.make_dataclass(
    "NotchConfig", [_field(spec) for spec in NOTCH_SETTINGS], frozen=True,
    namespace={"__doc__": _docstring(), "__post_init__": _check, "replaced": _replaced,
               "__module__": __name__})


class Settings:
    """The settings in force, the loop's rate (Hz) and the number of struts.

    Args:
        config: the settings (NotchConfig).
        sample_rate_hz: loop rate fs (Hz).
        channels: number of struts C.
    """

    def __init__(self, config: NotchConfig, sample_rate_hz: float, channels: int) -> None:
        """Hold ``config`` until :meth:`set_mu` or the supervisor replaces it."""
        self.config = config
        self.fs = float(sample_rate_hz)
        self.channels = int(channels)
        self.update_lowpass_hz = update_lowpass_corner_hz(vars(config))
        """The update low-pass corner in force (Hz; ``update_lowpass_hz`` resolved at
        start-up, :func:`~hexapod_vibration.parameter_specs.update_lowpass_corner_hz`)."""

    @property
    def ramp_samples(self) -> int:
        """Ramp length (samples) for enabling and removed tones (``ramp_s``)."""
        return int(round(self.config.ramp_s * self.fs))

    @property
    def fade_out_samples(self) -> int:
        """Length (samples) of the output's smooth fade when control is switched off.

        ``ramp_s``, at least :data:`~hexapod_vibration.core.control.notch.FADE_S`: a
        shorter fade of a cancelled line splatters it over the bands beside it.
        """
        return max(self.ramp_samples, int(round(FADE_S * self.fs)))

    def set_mu(self, mu: float) -> None:
        """The supervisor set ``mu`` itself (a clamp, a lowered rate): the setting follows."""
        self.config = self.config.replaced({"mu": mu})
