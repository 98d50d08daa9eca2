"""The notch's settings: safe defaults, combinations refused on every route, the paper preset.

A combination of settings that cannot work is refused with one reason wherever it is set:
the node's joint checks (``parameter_specs``: ``--ros-args``, a params file, ``ros2 param
set``), the core's settings (:class:`NotchConfig`), a scenario's ``notch:`` section and a
running supervisor's ``check``. The paper's algorithm is the preset ``paper``
(``config/presets/paper.yaml``).
"""

import numpy as np
import pytest
import yaml
from supervisor_checks import assert_refused_and_unchanged

from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.sim.scenario import (
    available_presets,
    load_scenario,
    notch_preset,
    scenario_from_dict,
)
from hexapod_vibration.core.sim.timeline import control_on_conflict
from hexapod_vibration.parameter_specs import (
    AUTO_UPDATE_LOWPASS_HZ,
    NOTCH_CONTROLLER,
    update_lowpass_corner_hz,
)
from hexapod_vibration.paths import config_path, scenario_path

TRACKING_NEEDS_BROADBAND = "frequency_tracking needs identification: broadband"
AUTO_NEEDS_BROADBAND = "mu_policy auto needs identification: broadband"
REFUSED = [
    ({"identification": "tones"}, AUTO_NEEDS_BROADBAND),
    ({"identification": "tones", "frequency_tracking": True}, AUTO_NEEDS_BROADBAND),
    ({"identification": "tones", "mu_policy": "manual", "frequency_tracking": True},
     TRACKING_NEEDS_BROADBAND),
    ({"identification": "tones", "mu_policy": "manual", "reference_harmonics": [1.0]},
     "reference_harmonics needs identification: broadband"),
    ({"update_lowpass_hz": -0.5}, "update_lowpass_hz = -0.5 Hz: must be -1"),
]
"""Combinations that cannot work (changes from the defaults) and their reasons."""


def _scenario(notch: dict) -> dict:
    """A scenario's YAML (a Table 1 shaker) with this ``notch:`` section."""
    return {"name": "mine", "duration_s": 42.0, "control_on_s": 22.0,
            "shaker": {"frequencies_hz": [40.0], "amplitudes_n": [80.0]}, "notch": notch}


def test_every_default_is_the_safe_choice():
    """The auto policy within 0.7 dB, broadband identification, the update low-pass automatic."""
    defaults = NOTCH_CONTROLLER.defaults()
    assert defaults["mu_policy"] == "auto" and defaults["max_rise_db"] == 0.7
    assert defaults["identification"] == "broadband" and defaults["divergence_guard"]
    assert defaults["update_lowpass_hz"] == -1.0
    assert update_lowpass_corner_hz(defaults) == AUTO_UPDATE_LOWPASS_HZ == 10.0
    for moving in ({"frequency_tracking": True}, {"reference_harmonics": [1.0, 2.0]}):
        assert update_lowpass_corner_hz({**defaults, **moving}) == 0.0
    assert update_lowpass_corner_hz({**defaults, "update_lowpass_hz": 5.0,
                                     "frequency_tracking": True}) == 5.0
    assert NOTCH_CONTROLLER.check(defaults) == ""


@pytest.mark.parametrize("changes, reason", REFUSED)
def test_a_combination_that_cannot_work_is_refused_on_every_route(changes, reason):
    """The same reason from the node's checks, the core's settings, a scenario, a supervisor."""
    values = {**NOTCH_CONTROLLER.defaults(), **changes}
    assert NOTCH_CONTROLLER.check(values).startswith(reason)          # -p, params file
    assert NOTCH_CONTROLLER.check(values, list(changes)).startswith(reason)   # param set
    with pytest.raises(ValueError, match=reason):
        NotchConfig().replaced(changes)
    with pytest.raises(ValueError, match=f"^notch: {reason}"):
        scenario_from_dict(_scenario({"tone_frequencies_hz": [40.0], **changes}))
    assert_refused_and_unchanged(NotchSupervisor(NotchConfig(tone_frequencies_hz=(40.0,))),
                                 changes, reason)


def test_one_setting_changed_from_the_defaults_is_taken_or_refused_with_the_reason():
    """Each works with the others at their defaults, or says which other one to change."""
    for name, value in (("frequency_tracking", True), ("mu_policy", "manual"),
                        ("update_lowpass_hz", 0.0), ("update_lowpass_hz", 10.0),
                        ("max_rise_db", 3.0), ("adaptation", "centralized"),
                        ("harmonics", 1), ("reference_harmonics", [1.0]),
                        ("divergence_guard", False), ("mu", 0.006)):
        config = NotchConfig().replaced({"tone_frequencies_hz": [40.0], name: value})
        NotchSupervisor(config)                      # accepted at start-up
    reason = NOTCH_CONTROLLER.check({**NOTCH_CONTROLLER.defaults(),
                                     "identification": "tones"}, ["identification"])
    assert "set mu_policy manual first" in reason, reason


def test_the_paper_preset_is_a_params_file_and_a_scenario_setting():
    """``paper``: test tones, eq. 18, mu 0.002 on every tone, the paper's update."""
    assert "paper" in available_presets()
    paper = notch_preset("paper")
    assert paper == {"mu_policy": "manual", "max_rise_db": 3.0, "identification": "tones",
                     "mu": 0.002, "adaptation": "decentralized", "update_lowpass_hz": 0.0}
    params = yaml.safe_load(config_path("presets/paper.yaml").read_text())
    assert params["notch_controller"]["ros__parameters"] == paper      # --params-file
    assert NOTCH_CONTROLLER.check({**NOTCH_CONTROLLER.defaults(), **paper}) == ""
    scenario = scenario_from_dict(_scenario({"preset": "paper",
                                             "tone_frequencies_hz": [40.0, 80.0]}))
    assert scenario.notch.mu == 0.002 and scenario.notch.settings == {
        k: v for k, v in paper.items() if k not in ("mu", "adaptation")}
    own = scenario_from_dict(_scenario({"preset": "paper", "tone_frequencies_hz": [40.0],
                                        "mu": 0.001, "update_lowpass_hz": 10.0}))
    assert own.notch.mu == 0.001 and own.notch.settings["update_lowpass_hz"] == 10.0
    with pytest.raises(ValueError, match="^notch: unknown preset 'papr'; presets: .*paper"):
        scenario_from_dict(_scenario({"preset": "papr", "tone_frequencies_hz": [40.0]}))
    rise = load_scenario(scenario_path("harmonic_rise"))           # a shipped one uses it
    assert rise.notch.settings["identification"] == "tones"
    assert not rise.notch.settings["divergence_guard"]


def test_the_shipped_scenarios_state_what_they_rely_on():
    """None leaves a setting whose default changed to its default (or a preset)."""
    changed = ("mu_policy", "identification", "update_lowpass_hz")
    for name in ("close_tones", "drift", "drift_tracking", "harmonic_rise",
                 "harmonic_rise_harmonics", "mismatch", "mismatch_tracking",
                 "single_tone_harmonic", "soak_drift", "spin_up", "spin_up_tachometer"):
        scenario = load_scenario(scenario_path(name))
        settings = scenario.notch.settings
        assert all(key in settings for key in changed), (name, settings)
        assert control_on_conflict(scenario, 1000.0) is None, name     # experiment runs it
        assert np.isfinite(settings["update_lowpass_hz"]) and settings["update_lowpass_hz"] >= 0
