"""One notch setting changed at any moment of the sequence: taken or refused, never a crash.

A user tunes a running controller with ``ros2 param set`` whenever they like: while the
plant is being identified, while the identification is analysed (one piece per sample),
or while control adapts. For every writable setting of the node's spec and a few values
of each (its bounds, its other choices), at one of those moments (:func:`cases_at`), on the
static rig (``test/static_rig.py``, the node's defaults: broadband identification, the
auto mu policy, the guard): the change is taken, or refused with a reason and nothing changed;
afterwards the supervisor keeps running (a change of tones at the wrong sample once
killed the node), its commands finite, and once nothing is being identified the 40 Hz
residual is no worse than without control.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from static_rig import coupled_gain, run, tone_rms

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.parameter_specs import NOTCH_CONTROLLER, ParameterSpec

K = coupled_gain(0.2)
ARRAYS = {"tone_frequencies_hz": ([40.0, 80.0], [80.0], [40.0, 120.0, 200.0]),
          "reference_harmonics": ([1.0],)}
"""Array values worth setting (the rig's tone is 40 Hz; one order per tone)."""
MOMENTS = ("identifying", "analysing", "adapting")
WORSE_DB = 1.0
"""The residual at 40 Hz may not exceed the uncontrolled one by more than this (dB)."""


def _inside(spec: ParameterSpec, bound: float, toward: float) -> float:
    """``bound`` itself, or (an open bound) 1 % of the way to ``toward``."""
    if (bound == spec.low and spec.low_open) or (bound == spec.high and spec.high_open):
        return bound + 0.01 * (toward - bound)
    return bound


def values_of(spec: ParameterSpec) -> tuple[Any, ...]:
    """Values of ``spec`` other than its default: the bounds, the other choices."""
    if spec.is_array:
        return ARRAYS[spec.name]
    if spec.type == "bool":
        return (not spec.default,)
    if spec.type == "string":
        return tuple(c for c in spec.choices if c != spec.default)
    low, high = spec.low, min(spec.high, 10 * max(abs(spec.default), 1.0))
    picked = {_inside(spec, low, high), _inside(spec, high, low)} - {spec.default}
    return tuple(int(v) if spec.type == "int" else v for v in sorted(picked))


def cases() -> list[tuple[str, Any]]:
    """Every (name, value) to set: the writable notch settings of the node's spec."""
    return [(spec.name, value) for spec in NOTCH_CONTROLLER.parameters
            if not spec.read_only and spec.name in NotchConfig.__dataclass_fields__
            for value in values_of(spec)]


def cases_at(moment: str) -> list[tuple[str, Any]]:
    """The cases tried at ``moment``: every third, in turn.

    Each case costs an analysis (~1 s of Nyquist tests on G(f)) before or after the change.
    """
    return cases()[MOMENTS.index(moment)::len(MOMENTS)]


def _defaults() -> NotchConfig:
    """The node's defaults on one 40 Hz tone, identification after 0.1 s."""
    return NotchConfig().replaced({"tone_frequencies_hz": [40.0], "identify_delay_s": 0.1})


def supervisor_at(moment: str) -> tuple[NotchSupervisor, int]:
    """A supervisor on the rig brought to ``moment``, and its next sample.

    Built each time: a copy would not do (``copy.deepcopy`` turns the canceller's views of
    its state into arrays of their own).
    """
    sup = NotchSupervisor(_defaults())
    if moment == "identifying":
        return sup, len(run(sup, K, 3000))
    n = len(run(sup, K, 20_000, until=lambda s: s.identification.analysis is not None))
    if moment == "analysing":
        return sup, n + len(run(sup, K, 3, n))             # a few pieces in
    n += len(run(sup, K, 20_000, n, until=lambda s: s.state == NotchState.ADAPTING))
    return sup, n + len(run(sup, K, 1000, n))


@pytest.fixture(scope="module")
def uncontrolled_rms() -> float:
    """The 40 Hz residual (m/s^2 RMS) with control never on."""
    sup = NotchSupervisor(NotchConfig().replaced({"tone_frequencies_hz": [40.0],
                                                  "enabled": False}))
    return tone_rms(run(sup, K, 2000))


@pytest.mark.parametrize("moment", MOMENTS)
def test_one_setting_at_any_moment_is_taken_or_refused(moment, uncontrolled_rms):
    for name, value in cases_at(moment):
        sup, n = supervisor_at(moment)
        before = sup.config
        try:
            sup.apply({name: value})
        except ValueError as exc:
            assert str(exc) and "\n" not in str(exc), (name, value)
            assert sup.config == before, (name, value)
            continue
        n += len(run(sup, K, 1000, n))
        n += len(run(sup, K, 14_000, n, until=lambda s: not s.identification.busy))
        assert not sup.identification.busy, (name, value, moment)
        residual = run(sup, K, 3000, n)
        assert np.all(np.isfinite(sup.canceller.weights)), (name, value, moment)
        level_db = 20 * np.log10(tone_rms(residual[-1000:]) / uncontrolled_rms)
        assert level_db <= WORSE_DB, (name, value, moment, sup.state, level_db)
