"""The experiment's params file carries the scenario's rotor to the driver (no ROS needed)."""

from hexapod_vibration.core.sim.scenario import scenario_from_dict
from hexapod_vibration.parameter_specs import PPH_DRIVER, rotor_arrays
from hexapod_vibration.tools.experiment import node_parameters

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
