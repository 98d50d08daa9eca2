"""Each node's parameters as its spec declares them: descriptors, start-up checks, unknowns.

- ``describe_parameters`` (``ros2 param describe``) returns exactly the descriptor made
  from the spec: the true range, the unit, read-only.
- A bad value given at start-up (``-p``) ends the node with exit 2 and one line whose
  reason is exactly the one a run-time ``ros2 param set`` of the same value gets.
- Parameters a node does not have are reported at start-up.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import yaml
from node_graph import HANG_GUARD_S, ParameterClient

from hexapod_vibration.parameter_specs import NODE_SPECS
from hexapod_vibration.ros.parameters import descriptor_for

STARTUP_REFUSALS = {
    "pph_driver": [
        {"shaker_frequencies_hz": "[600.0]"},
        {"shaker_amplitudes_n": "[1000.0]"},
        {"shaker_phases_rad": "[100.0]"},
        {"shaker_frequencies_hz": "[498.0]", "shaker_drift_hz": "2.0"},   # together
        {"command_timeout_samples": "0"},
    ],
    "notch_controller": [
        {"tone_frequencies_hz": "[0.0]"},                                   # open bound
        {"tone_frequencies_hz": "[40.0, 40.0]"},
        {"mu": "0.7"},                              # beyond the normalised bound 0.618
        {"adaptation": "fancy"},
    ],
    "pointing_controller": [
        {"target_translation_m": "[0.0, 0.0]"},
        {"target_tilt_x_deg": "2.0", "target_tilt_y_deg": "2.0"},           # norm > 2.5
    ],
}


def _python(text: str):
    return yaml.safe_load(text)


def test_descriptors_are_the_specs(ros_context, node_processes, tmp_path):
    args = {"pph_driver": ["--ros-args", "-p", "lockstep_controllers:=[]"],
            "pph_recorder": ["--ros-args", "-p", f'bag_path:={tmp_path / "bag"}']}
    names = ("pph_driver", "notch_controller", "pointing_controller", "pph_recorder")
    for name in names:
        node_processes.start(name, *args.get(name, []))
    node = ros_context.create_node("describer")
    for name in names:
        client = ParameterClient(ros_context, node, name)
        spec = NODE_SPECS[name]
        described = client._wait(client.client.describe_parameters(list(spec.names)))
        for parameter, actual in zip(spec.parameters, described.descriptors, strict=True):
            expected = descriptor_for(parameter)
            what = f"{name} {parameter.name}"
            assert actual.name == parameter.name, what
            assert actual.type == expected.type, what
            assert actual.description == expected.description, what
            assert actual.read_only == expected.read_only, what
            assert actual.additional_constraints == expected.additional_constraints, what
            assert [(r.from_value, r.to_value) for r in actual.floating_point_range] == [
                (r.from_value, r.to_value) for r in expected.floating_point_range], what
            assert [(r.from_value, r.to_value) for r in actual.integer_range] == [
                (r.from_value, r.to_value) for r in expected.integer_range], what


def test_start_up_refuses_what_run_time_refuses(ros_context, node_processes):
    startup_reasons = {}
    for name, cases in STARTUP_REFUSALS.items():
        for case in cases:
            overrides = [a for key, value in case.items() for a in ("-p", f"{key}:={value}")]
            process = node_processes.start(name, "--ros-args", *overrides)
            code = process.wait(HANG_GUARD_S)
            assert code == 2, (case, process.output())
            lines = process.stderr_path.read_text().strip().splitlines()
            errors = [line for line in lines if line.startswith(f"{name}: error: ")]
            assert len(errors) == 1 and "Traceback" not in process.output(), process.output()
            startup_reasons[(name, tuple(case.items()))] = errors[0][len(f"{name}: error: "):]
    running = {"pph_driver": node_processes.start("pph_driver", "--ros-args", "-p",
                                                  "lockstep_controllers:=[]"),
               "notch_controller": node_processes.start("notch_controller"),
               "pointing_controller": node_processes.start("pointing_controller")}
    node = ros_context.create_node("setter")
    for name, cases in STARTUP_REFUSALS.items():
        client = ParameterClient(ros_context, node, name)
        for case in cases:
            items = list(case.items())
            for key, value in items[:-1]:            # the first ones alone are fine
                assert client.set(key, _python(value)).successful, (name, key)
            key, value = items[-1]
            result = client.set(key, _python(value))
            assert not result.successful, (name, case)
            assert result.reason == startup_reasons[(name, tuple(case.items()))], (name, case)
            for key, _ in items[:-1]:                # back to the defaults
                default = NODE_SPECS[name][key].default
                assert client.set(key, default).successful, (name, key)
    assert all(p.running() for p in running.values())


def test_a_command_delay_the_loop_delay_cannot_take_is_refused(node_processes):
    process = node_processes.start("notch_controller", "--ros-args", "-p",
                                   "loop_delay_samples:=19.0", "-p", "command_delay_samples:=2")
    assert process.wait(HANG_GUARD_S) == 2, process.output()
    errors = [line for line in process.stderr_path.read_text().splitlines()
              if line.startswith("notch_controller: error: ")]
    assert errors == ["notch_controller: error: loop_delay_samples 19 + command_delay_samples "
                      "2 = 21 samples of loop delay, more than 20"], process.output()


def test_unknown_parameters_are_reported(node_processes, tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({"pph_driver": {"ros__parameters": {
        "shaker_frequency_hz": [40.0], "seed": 3}}}))
    process = node_processes.start("pph_driver", "--ros-args", "--params-file", str(params),
                                   "-p", "mu:=0.01", "-p", "lockstep_controllers:=[]")
    deadline_output = ""
    for _ in range(int(HANG_GUARD_S / 0.1)):
        deadline_output = process.output()
        if "PPH driver up" in deadline_output or not process.running():
            break
        process.wait(0.1)
    assert "unknown parameter(s) ignored: mu, shaker_frequency_hz" in deadline_output, \
        deadline_output
    assert process.running(), deadline_output
    assert "seed" not in deadline_output.split("unknown parameter(s) ignored:")[1].split("(")[0]


def test_params_file_in_the_package_is_complete():
    root = Path(__file__).resolve().parents[2]
    params = yaml.safe_load((root / "config" / "pph.yaml").read_text())
    for name in ("pph_driver", "notch_controller", "pointing_controller"):
        assert set(params[name]["ros__parameters"]) == set(NODE_SPECS[name].names)


def test_a_refusal_after_the_analysis_worker_started_leaves_one_line(ros_env):
    """``identification_analysis:=process`` starts the worker before the settings' whole check.

    The refusal still ends the node with its one line: the worker is shut down (left
    running, its queues' semaphores were reported leaked by multiprocessing's resource
    tracker, which writes after the node's exit: the output is read to its end, when every
    process holding it has closed it).
    """
    command = [str(Path(sys.executable).parent / "notch_controller"), "--ros-args",
               "-p", "identification_analysis:=process",
               "-p", "tone_frequencies_hz:=[400.0]", "-p", "harmonics:=3"]
    result = subprocess.run(command, env=ros_env, capture_output=True, text=True,
                            timeout=HANG_GUARD_S, check=False)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [
        "notch_controller: error: tone frequencies must be in (0, 500) Hz (fs/2), "
        "got [800.0, 1200.0, 1600.0]"], result.stderr
