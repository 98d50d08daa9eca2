"""parameter_specs: one declaration per parameter; the files and descriptors derived from it."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import yaml

from hexapod_vibration import parameter_specs as specs
from hexapod_vibration.ros.parameters import descriptor_for

ROOT = Path(__file__).resolve().parents[1]


def test_params_yaml_is_generated_from_the_specs():
    assert (ROOT / "config" / "pph.yaml").read_text() == specs.params_yaml(), (
        "config/pph.yaml differs from parameter_specs: run "
        "python -m hexapod_vibration.parameter_specs --write-config")
    params = yaml.safe_load(specs.params_yaml())
    for node in specs.LOOP_NODES:
        assert params[node]["ros__parameters"] == specs.NODE_SPECS[node].defaults()


def test_spec_constants_are_the_cores():
    from hexapod_vibration.analysis.report_windows import DEFAULT_WINDOW_S
    from hexapod_vibration.core.control import adaptation, mu_policy
    from hexapod_vibration.core.control.notch_supervisor import NotchConfig
    from hexapod_vibration.tools import analyze

    assert adaptation.ADAPTATION_MODES is specs.ADAPTATION_MODES        # one definition
    assert mu_policy.MU_POLICIES is specs.MU_POLICIES
    notch = specs.NOTCH_CONTROLLER.defaults()
    for name, value in vars(NotchConfig()).items():
        expected = list(value) if isinstance(value, tuple) else value
        assert notch[name] == expected, name
    own = {spec.name for spec in specs.LOOP_SCHEDULING}             # the loop's scheduling
    assert set(vars(NotchConfig())) == set(notch) - own
    assert analyze.DEFAULT_WINDOW_S == DEFAULT_WINDOW_S
    from hexapod_vibration.analysis import twin
    assert analyze.DEFAULT_TWIN_SEGMENT_S == twin.DEFAULT_SEGMENT_S


def test_descriptors_state_the_true_range():
    tones = specs.NOTCH_CONTROLLER["tone_frequencies_hz"]
    descriptor = descriptor_for(tones)
    assert "each in (0, 500)" in descriptor.additional_constraints
    assert "[0, 500]" not in descriptor.additional_constraints
    for bad in (0.0, 500.0, -1.0, math.nan):
        assert tones.check([bad]), bad
    assert tones.check([1e-9, 499.999]) == ""
    mu = descriptor_for(specs.NOTCH_CONTROLLER["mu"])
    assert (mu.floating_point_range[0].from_value, mu.floating_point_range[0].to_value) == (
        0.0, 1.0)
    assert "stability bound" in mu.additional_constraints
    seed = descriptor_for(specs.PPH_DRIVER["seed"])
    assert (seed.integer_range[0].from_value, seed.integer_range[0].to_value) == (0, 2**31 - 1)
    assert descriptor_for(specs.PPH_DRIVER["clock_mode"]).read_only


@pytest.mark.parametrize("node", sorted(specs.NODE_SPECS))
def test_every_closed_range_is_exactly_what_the_check_accepts(node):
    for spec in specs.NODE_SPECS[node].parameters:
        if spec.low is None or spec.high is None or spec.element_type not in ("double", "int"):
            continue
        wrap = (lambda v: [v]) if spec.is_array else (lambda v: v)
        kind = float if spec.element_type == "double" else int
        if spec.length:
            wrap = (lambda v, n=spec.length: [v] * n)  # noqa: E731
        for edge, is_open in ((spec.low, spec.low_open), (spec.high, spec.high_open)):
            assert bool(spec.check(wrap(kind(edge)))) == is_open, (spec.name, edge)
        step = 1 if kind is int else max(abs(spec.high - spec.low) * 1e-3, 1e-9)
        assert spec.check(wrap(kind(spec.low - step))), spec.name
        assert spec.check(wrap(kind(spec.high + step))), spec.name


def test_reasons_name_the_parameter_and_the_range():
    driver = specs.PPH_DRIVER
    values = driver.defaults()
    for name, value, words in (("shaker_frequencies_hz", [600.0], ("maximum", "[0.1, 499]")),
                               ("shaker_amplitudes_n", [1000.0], ("maximum", "[0, 100]")),
                               ("shaker_phases_rad", [100.0], ("maximum", "[-10, 10]")),
                               ("shaker_amplitudes_n", [math.nan], ("finite",)),
                               ("lockstep_controllers", ["notch", "x"], ("not one of",)),
                               ("lockstep_controllers", ["notch", "notch"], ("duplicate",)),
                               ("shaker_frequencies_hz", [40.0] * 17, ("at most 16",))):
        reason = driver.check({**values, name: value}, [name])
        assert name in reason and all(w in reason for w in words), reason
    pointing = specs.POINTING_CONTROLLER
    reason = pointing.check({**pointing.defaults(), "target_translation_m": [0.0, 0.0]},
                            ["target_translation_m"])
    assert reason == "target_translation_m needs 3 values (m), got 2"


def test_shaker_arrays_pair_by_index_in_any_order():
    values = specs.PPH_DRIVER.defaults()
    two = {**values, "shaker_frequencies_hz": [39.0, 40.0]}   # amplitudes still [80.0]
    assert specs.PPH_DRIVER.check(two) == ""
    assert specs.shaker_tone_arrays(two) == ([39.0], [80.0], [0.0])
    assert "waiting for a partner: 1 of shaker_frequencies_hz" in specs.shaker_unpaired(two)
    both = {**two, "shaker_amplitudes_n": [40.0, 40.0], "shaker_phases_rad": [0.5]}
    assert specs.shaker_tone_arrays(both) == ([39.0, 40.0], [40.0, 40.0], [0.5, 0.0])
    assert specs.shaker_unpaired(both) == ""
    # The joint check: a tone drifting out of (0, 500) Hz is refused, at start-up or later.
    drifting = {**values, "shaker_frequencies_hz": [40.0, 497.0],
                "shaker_amplitudes_n": [80.0, 1.0], "shaker_drift_hz": 4.0}
    assert "shaker_drift_hz" in specs.PPH_DRIVER.check(drifting)
    silent = {**drifting, "shaker_amplitudes_n": [80.0]}        # 497 Hz does not sound
    assert specs.PPH_DRIVER.check(silent) == ""


def test_a_spec_refuses_a_default_that_fails_it():
    with pytest.raises(ValueError, match="default"):
        specs.ParameterSpec("x", "double", 2.0, "x", low=0.0, high=1.0)
    with pytest.raises(ValueError, match="type"):
        specs.ParameterSpec("x", "float", 0.0, "x")


def test_generated_table_lists_every_parameter_once():
    table = specs.markdown_table()
    for node, spec in specs.NODE_SPECS.items():
        for name in spec.names:
            assert re.search(rf"`{name}`", table), (node, name)
