"""The experiment's params file carries the scenario's rotor to the driver (no ROS needed)."""

from hexapod_vibration.core.sim.scenario import scenario_from_dict
from hexapod_vibration.parameter_specs import PPH_DRIVER, rotor_arrays
from hexapod_vibration.tools.experiment_setup import node_parameters

BASE = {"name": "spin", "duration_s": 4.0, "control_on_s": 2.0, "window_s": 1.0}
ROTOR = {"orders": [1.0, 2.0, 3.0], "amplitudes_n": [20.0, 5.0, 2.0],
         "reference_speed_hz": 50.0, "profile_time_s": [2.0, 22.0],
         "profile_speed_hz": [30.0, 50.0], "tachometer": True}


def test_the_rotor_goes_to_the_driver_as_its_parameters():
    driver = node_parameters(scenario_from_dict({**BASE, "rotor": ROTOR}),
                             "lockstep")["pph_driver"]["ros__parameters"]
    assert {k: v for k, v in driver.items() if k.startswith("rotor_")} == {
        f"rotor_{k}": v for k, v in ROTOR.items()}
    values = {**PPH_DRIVER.defaults(), **driver}
    assert PPH_DRIVER.check(values) == ""
    assert rotor_arrays(values) == (ROTOR["orders"], ROTOR["amplitudes_n"],
                                    ROTOR["profile_time_s"], ROTOR["profile_speed_hz"])


def test_no_rotor_section_sets_no_rotor_parameter():
    driver = node_parameters(scenario_from_dict(BASE), "lockstep")["pph_driver"]
    assert not any(k.startswith("rotor_") for k in driver["ros__parameters"])


def test_model_overrides_reach_the_nodes_as_a_model_file(tmp_path):
    """harmonic_rise's payload-mounted shaker: the driver simulates the overridden model."""
    import pytest
    import yaml

    from hexapod_vibration.core.model.config import load_model_config
    from hexapod_vibration.core.sim.scenario import load_scenario
    from hexapod_vibration.paths import config_path, scenario_path
    from hexapod_vibration.tools.experiment_setup import model_file_text

    scenario = load_scenario(scenario_path("harmonic_rise"))
    path = tmp_path / "model.yaml"
    path.write_text(model_file_text(scenario))
    written = load_model_config(path)
    expected = load_model_config(config_path("pph_model.yaml"), scenario.model_overrides)
    assert repr(written) == repr(expected)
    assert written.shaker.mounted_on == "top_plate"
    params = node_parameters(scenario, "lockstep", str(path))
    for node in ("pph_driver", "pointing_controller"):
        assert params[node]["ros__parameters"]["model_file"] == str(path)
    assert model_file_text(scenario_from_dict(BASE)) == ""
    bad = scenario_from_dict({**BASE, "model_overrides": {"shaker": {"mass_kg": 1.0}}})
    with pytest.raises(ValueError, match="mass_kg"):
        model_file_text(bad)
    assert "model_file" not in yaml.safe_dump(node_parameters(bad, "lockstep"))


def test_twin_is_refused_with_demo_realtime_or_an_existing_twin_bag(tmp_path):
    import pytest

    from hexapod_vibration.tools.experiment import build_parser, check_arguments

    def check(*argv):
        return check_arguments(build_parser().parse_args(["--out", str(tmp_path), *argv]))

    with pytest.raises(ValueError, match="--twin: not with --demo"):
        check("--demo", "--twin")
    with pytest.raises(ValueError, match="--twin: needs --lockstep"):
        check("--scenario", "mismatch", "--twin", "--realtime")
    (tmp_path / "twin" / "bag").mkdir(parents=True)
    with pytest.raises(ValueError, match="twin/bag exists"):
        check("--scenario", "mismatch", "--twin")
    assert check("--scenario", "mismatch")         # no --twin: the twin's folder is not ours


def test_the_twin_scenario_never_switches_control_on():
    from hexapod_vibration.tools.experiment_run import twin_scenario
    from hexapod_vibration.tools.experiment_setup import run_record

    scenario = scenario_from_dict({**BASE, "notch": {"tone_frequencies_hz": [40.0]}})
    twin = twin_scenario(scenario)
    assert twin.control_on_s == twin.duration_s == scenario.duration_s
    assert twin.seed == scenario.seed and twin.identify_at_s == scenario.identify_at_s
    assert run_record(twin, "lockstep").control_on_sample == -1


def test_notch_settings_the_controller_refuses_are_refused_with_the_scenario():
    """Checked as the controller would at start-up, before a run brings anything up."""
    import pytest

    notch = {"tone_frequencies_hz": [40.0], "update_lowpass_hz": 10.0}
    scenario = scenario_from_dict({**BASE, "notch": notch})
    assert node_parameters(scenario, "lockstep")["notch_controller"]["ros__parameters"][
        "update_lowpass_hz"] == 10.0
    with pytest.raises(ValueError, match="notch: update_lowpass_hz = 600 Hz is above the "
                                         "maximum: update_lowpass_hz must be"):
        scenario_from_dict({**BASE, "notch": {**notch, "update_lowpass_hz": 600.0}})
    with pytest.raises(ValueError, match="notch: .*reference_harmonics needs one order"):
        scenario_from_dict({**BASE, "notch": {**notch, "reference_harmonics": [1.0, 2.0]}})


def test_a_realtime_priority_goes_to_every_loop_node_and_only_when_asked():
    from hexapod_vibration.core.sim.scenario import load_scenario
    from hexapod_vibration.paths import scenario_path

    scenario = load_scenario(scenario_path("single_tone_harmonic"))
    params = node_parameters(scenario, "realtime", realtime_priority=50)
    assert {node: p["ros__parameters"].get("realtime_priority") for node, p in params.items()} \
        == {"pph_driver": 50, "pointing_controller": 50, "notch_controller": 50}
    assert all("realtime_priority" not in p["ros__parameters"]
               for p in node_parameters(scenario, "realtime").values())


def test_a_realtime_experiment_pipelines_the_commands_and_the_notch_knows_it():
    from hexapod_vibration.core.sim.scenario import load_scenario
    from hexapod_vibration.parameter_specs import NOTCH_CONTROLLER
    from hexapod_vibration.paths import scenario_path
    from hexapod_vibration.tools.experiment_setup import REALTIME_COMMAND_DELAY_SAMPLES

    scenario = load_scenario(scenario_path("single_tone_harmonic"))
    base = NOTCH_CONTROLLER["loop_delay_samples"].default
    realtime = {n: p["ros__parameters"] for n, p in node_parameters(scenario, "realtime").items()}
    assert REALTIME_COMMAND_DELAY_SAMPLES >= 1
    for node in ("pph_driver", "notch_controller", "pointing_controller"):
        assert realtime[node]["command_delay_samples"] == REALTIME_COMMAND_DELAY_SAMPLES
    assert realtime["notch_controller"].get("loop_delay_samples", base) == base  # node adds d
    lockstep = {n: p["ros__parameters"] for n, p in node_parameters(scenario, "lockstep").items()}
    assert "command_delay_samples" not in lockstep["pph_driver"]
    assert "loop_delay_samples" not in lockstep["notch_controller"]
