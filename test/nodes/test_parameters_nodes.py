"""Every parameter of the three nodes through rclpy's parameter client (as ``ros2 param``).

Each node runs as a process on the test's own ROS domain. A valid value is accepted, read
back with get_parameters and, where it is observable, seen in the data (by sample index,
"eventually", never timed); each bad value is rejected with a non-empty reason and the
old value kept. ``config/pph.yaml`` holds every parameter at its default, and a params
file given with ``--ros-args --params-file`` is applied. Notch settings that cannot work
together are refused at start-up and at run time with the same reason.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml
from node_graph import (
    HANG_GUARD_S,
    Diagnostics,
    ParameterClient,
    StrutTopic,
    assert_close,
    assert_rejected,
    db,
    start_pointing_loop,
    tone_amplitude,
    wait_until,
)
from rclpy.parameter import Parameter

ROOT = Path(__file__).resolve().parents[2]
PARAMS_FILE = ROOT / "config" / "pph.yaml"
NODES = ("pph_driver", "notch_controller", "pointing_controller")
RCLPY_OWN = {"use_sim_time", "start_type_description_service"}
EMPTY_DEFAULTS: dict = {}
"""Parameters a params file cannot hold: none (an empty array arrives unset, read as [])."""


def _check_rejected(client: ParameterClient, name: str, bad_values, *words: str) -> None:
    """Each bad value is rejected with a reason (containing ``words``); value unchanged."""
    before = client.get(name)[name]
    for bad in bad_values:
        result = client.set(name, bad)
        try:
            assert_rejected(result, *words)
        except AssertionError as exc:
            raise AssertionError(f"{client.target} {name}={bad!r}: {exc}") from None
        assert_close(client.get(name)[name], before)


def _check_accepted(client: ParameterClient, name: str, value) -> None:
    result = client.set(name, value)
    assert result.successful, f"{client.target} {name}={value!r}: {result.reason}"
    assert_close(client.get(name)[name], value)


def _check_read_only(client: ParameterClient, values: dict) -> None:
    for name, value in values.items():
        _check_rejected(client, name, [value], "read-only")


def test_params_yaml_holds_every_parameter_at_its_default(ros_context, node_processes):
    for name in NODES:
        node_processes.start(name)
    node = ros_context.create_node("param_reader")
    expected = yaml.safe_load(PARAMS_FILE.read_text())
    for name in NODES:
        actual = ParameterClient(ros_context, node, name).get_all()
        for own in RCLPY_OWN:
            actual.pop(own)
        documented = {**expected[name]["ros__parameters"], **EMPTY_DEFAULTS.get(name, {})}
        assert actual == documented, name


def test_params_file_is_applied(ros_context, node_processes, tmp_path):
    params = yaml.safe_load(PARAMS_FILE.read_text())
    changed = {
        "pph_driver": {"shaker_frequencies_hz": [45.0, 90.0], "shaker_amplitudes_n": [60.0, 5.0],
                       "shaker_phases_rad": [0.0, 1.5], "command_timeout_samples": 7,
                       "clock_mode": "realtime", "lockstep_controllers": ["pointing"]},
        "notch_controller": {"mu": 0.004, "tone_frequencies_hz": [45.0, 90.0],
                             "enabled": False, "adaptation": "centralized",
                             "identify_delay_s": 0.5, "dc_cutoff_hz": 0.25},
        "pointing_controller": {"target_tilt_x_deg": 1.0, "target_twist_deg": -2.0,
                                "target_translation_m": [0.0, 1e-4, 0.0],
                                "bandwidth_hz": 1.0},
    }
    for name, values in changed.items():
        params[name]["ros__parameters"].update(values)
    path = tmp_path / "my_pph.yaml"
    path.write_text(yaml.safe_dump(params))
    for name in NODES:
        node_processes.start(name, "--ros-args", "--params-file", str(path))
    node = ros_context.create_node("param_reader")
    for name, values in changed.items():
        client = ParameterClient(ros_context, node, name)
        actual = client.get(*values)
        for key, value in values.items():
            assert_close(actual[key], value)
        # The rest is at the defaults of the file.
        others = client.get_all()
        for key, value in params[name]["ros__parameters"].items():
            assert_close(others[key], value)


def test_notch_controller_parameters(ros_context, node_processes):
    driver = node_processes.start("pph_driver", "--ros-args", "-p",
                                  "lockstep_controllers:=[notch]")
    # The tone identification (3.2 s of samples) instead of the 10 s broadband one: the
    # parameters' handling is the same, and this test identifies twice.
    notch = node_processes.start("notch_controller", "--ros-args",
                                 "-p", "tone_frequencies_hz:=[40.0]", "-p", "mu:=0.01",
                                 "-p", "identify_delay_s:=0.2", "-p", "identification:=tones",
                                 "-p", "mu_policy:=manual")
    node = ros_context.create_node("param_client")
    command = StrutTopic(node, "/pph/notch_command")
    diagnostics = Diagnostics(node)
    client = ParameterClient(ros_context, node, "notch_controller")

    def logs() -> str:
        return driver.output() + notch.output()

    def identified(tones: list[float]) -> bool:
        return (diagnostics.value("notch_controller", "state") == "adapting"
                and diagnostics.value("notch_controller", "identified_tones_hz") == str(tones))

    assert wait_until(ros_context, lambda: identified([40.0]), HANG_GUARD_S), logs()
    bound = float(diagnostics.value("notch_controller", "mu_bound"))
    assert 0.0 < bound < 0.9

    # mu
    _check_accepted(client, "mu", 0.005)
    _check_rejected(client, "mu", [-0.1, math.nan, math.inf, -math.inf, "fast", 1])
    _check_rejected(client, "mu", [0.9, min(bound * 1.01, 1.0)], "stability bound",
                    f"{bound:.4g}")
    # adaptation
    _check_rejected(client, "adaptation", ["magic", ""], "adaptation")
    _check_rejected(client, "adaptation", [3.0])
    _check_accepted(client, "adaptation", "centralized")
    _check_accepted(client, "adaptation", "decentralized")
    # tone_frequencies_hz
    _check_rejected(client, "tone_frequencies_hz", [[math.nan], [40.0, math.nan], [math.inf]],
                    "finite")
    _check_rejected(client, "tone_frequencies_hz", [[-40.0], [0.0], [500.0], [40.0, 600.0]],
                    "500")
    _check_rejected(client, "tone_frequencies_hz", [[40.0, 40.0], [80.0, 40.0, 80.0]],
                    "duplicate")
    _check_rejected(client, "tone_frequencies_hz", [[10.0 + 20.0 * k for k in range(17)]],
                    "16")
    _check_rejected(client, "tone_frequencies_hz", ["40", [40, 80], 40.0])  # wrong types
    # A new tone: accepted, identified (it was unknown), then adapted.
    _check_accepted(client, "tone_frequencies_hz", [40.0, 80.0])
    assert wait_until(ros_context, lambda: identified([40.0, 80.0]), HANG_GUARD_S), logs()
    # Removing a tone needs no identification (bumpless).
    statuses = len(diagnostics.history)
    mark = command.last_index
    _check_accepted(client, "tone_frequencies_hz", [40.0])
    later = []

    def two_later_statuses() -> bool:
        later[:] = [s for s in diagnostics.history[statuses:] if s.name == "notch_controller"
                    and int({kv.key: kv.value for kv in s.values}["last_sample"]) > mark]
        return len(later) >= 2
    assert wait_until(ros_context, two_later_statuses, HANG_GUARD_S), logs()
    assert all(s.message == "adapting" for s in later), [s.message for s in later]

    # enabled: off -> the command fades to exactly zero; on -> it comes back.
    def commands_after(start: int) -> np.ndarray:
        return command.window(start, command.last_index + 1)[1]

    _check_accepted(client, "enabled", False)
    mark = command.last_index
    off = wait_until(ros_context,
        lambda: len(commands_after(mark)) > 200
        and not np.any(commands_after(mark)[-100:]), HANG_GUARD_S)
    assert off, commands_after(mark)[-5:]
    _check_accepted(client, "enabled", True)
    mark = command.last_index
    assert wait_until(ros_context,
        lambda: np.any(np.abs(commands_after(mark)) > 0.01), HANG_GUARD_S)
    _check_rejected(client, "enabled", ["yes", 1])

    # The other run-time parameters.
    for name, good, bad in (("ramp_s", 0.1, [-1.0, 6.0, math.nan]),
                            ("identify_delay_s", 2.0, [-1.0, 61.0]),
                            ("identification_amplitude_n", 3.0, [0.0, -1.0, 21.0]),
                            ("auto_identify", False, ["no"])):
        _check_accepted(client, name, good)
        _check_rejected(client, name, bad)
    _check_read_only(client, {"identification_settle_s": 0.2, "identification_measure_s": 0.5,
                              "dc_cutoff_hz": 1.0, "loop_delay_samples": 1.0,
                              "executor": "events"})
    assert notch.running() and driver.running(), logs()


def test_driver_parameters(ros_context, node_processes):
    driver = node_processes.start("pph_driver", "--ros-args", "-p", "clock_mode:=realtime",
                                  "-p", "lockstep_controllers:=[]")
    node = ros_context.create_node("param_client")
    accel = StrutTopic(node, "/pph/accel")
    force = StrutTopic(node, "/pph/actuator_force")
    client = ParameterClient(ros_context, node, "pph_driver")
    assert client.get("clock_mode", "lockstep_controllers") == {
        "clock_mode": "realtime", "lockstep_controllers": []}

    # The shaker tone is in the accelerometers, and gone once its amplitude is 0.
    assert wait_until(ros_context, lambda: accel.last_index > 1500, HANG_GUARD_S), driver.output()
    on = tone_amplitude(*accel.window(accel.last_index - 1000, accel.last_index + 1), 40.0)
    _check_accepted(client, "shaker_amplitudes_n", [0.0])
    mark = accel.last_index
    assert wait_until(ros_context, lambda: accel.last_index > mark + 3000, HANG_GUARD_S)
    off = tone_amplitude(*accel.window(mark + 2000, mark + 3000), 40.0)
    assert np.all(on > 0.05) and db(np.linalg.norm(on) / np.linalg.norm(off)) > 20.0, (on, off)

    # Shaker arrays: paired by index (each can be set alone, in any order; a value
    # without its partner waits, inert), elements within bounds and finite, checked together.
    _check_accepted(client, "shaker_frequencies_hz", [40.0, 80.0])   # 80 Hz: no amplitude
    _check_accepted(client, "shaker_phases_rad", [0.1, 0.2])
    _check_accepted(client, "shaker_frequencies_hz", [40.0])
    _check_accepted(client, "shaker_phases_rad", [])
    result = client.set_atomically(shaker_frequencies_hz=[40.0, 80.0],
                                   shaker_amplitudes_n=[80.0, 10.0])
    assert result.successful, result.reason
    assert client.get("shaker_frequencies_hz", "shaker_amplitudes_n") == {
        "shaker_frequencies_hz": [40.0, 80.0], "shaker_amplitudes_n": [80.0, 10.0]}
    _check_accepted(client, "shaker_phases_rad", [0.0, 1.0])
    _check_rejected(client, "shaker_amplitudes_n", [[-1.0, 10.0]], "minimum")
    _check_rejected(client, "shaker_amplitudes_n", [[150.0, 10.0]], "maximum")
    _check_rejected(client, "shaker_amplitudes_n", [[math.nan, 10.0]], "finite")
    _check_rejected(client, "shaker_amplitudes_n", ["loud", [80, 10]])
    _check_rejected(client, "shaker_frequencies_hz", [[600.0, 80.0], [0.0, 80.0]])
    _check_rejected(client, "shaker_frequencies_hz", [[math.nan, 80.0]], "finite")
    _check_rejected(client, "shaker_phases_rad", [[0.0, 11.0]], "maximum")

    # The paper's test sine: the same force on all six actuators.
    _check_accepted(client, "test_sine_amplitude_n", 5.0)
    _check_accepted(client, "test_sine_frequency_hz", 45.0)

    def sine_applied() -> bool:
        _, f = force.window(force.last_index - 200, force.last_index + 1)
        return (len(f) > 150 and np.allclose(f, f[:, :1])
                and 4.5 < np.max(np.abs(f)) <= 5.0 + 1e-9)
    assert wait_until(ros_context, sine_applied, HANG_GUARD_S), (
        force.window(force.last_index - 5, force.last_index + 1), driver.output())
    _check_accepted(client, "test_sine_amplitude_n", 0.0)
    assert wait_until(ros_context,
        lambda: not np.any(force.window(force.last_index - 200, force.last_index + 1)[1]),
        HANG_GUARD_S), (accel.last_index, force.last_index, accel.messages, force.messages,
                        driver.running(), driver.output())
    _check_rejected(client, "test_sine_amplitude_n", [-1.0, 41.0, math.nan])
    _check_rejected(client, "test_sine_frequency_hz", [0.0, 500.0, math.inf])

    for name, good, bad in (("shaker_drift_hz", 0.5, [-0.1, 6.0, math.nan]),
                            ("shaker_drift_period_s", 30.0, [0.5, 4000.0]),
                            ("shaker_noise_rms_n", 1.0, [-1.0, 21.0]),
                            ("command_timeout_samples", 10, [0, 1001, 5.5]),
                            ("lockstep_timeout_s", 0.5, [0.0, 11.0, math.nan]),
                            ("hold_at_time_s", 100.0, [-2.0, math.nan])):
        _check_accepted(client, name, good)
        _check_rejected(client, name, bad)
    _check_accepted(client, "hold_at_time_s", -1.0)
    _check_read_only(client, {"clock_mode": "lockstep", "model_file": "/tmp/model.yaml",
                              "nonlinear": False, "seed": 2, "executor": "events",
                              "lockstep_controllers": ["notch"]})
    assert driver.running(), driver.output()
    last = accel.last_index
    assert wait_until(ros_context, lambda: accel.last_index > last + 100, HANG_GUARD_S)


def test_pointing_controller_parameters(ros_context, node_processes):
    driver, pointing = start_pointing_loop(node_processes)
    node = ros_context.create_node("param_client")
    command = StrutTopic(node, "/pph/pointing_command")
    client = ParameterClient(ros_context, node, "pointing_controller")

    def recent_mean(samples: int = 300) -> np.ndarray:
        return command.window(command.last_index - samples, command.last_index + 1)[1].mean(0)

    assert wait_until(ros_context, lambda: command.last_index > 2000, HANG_GUARD_S), (
        driver.output() + pointing.output())
    level = recent_mean()

    # A tilt set-point changes the forces that hold the plate.
    _check_accepted(client, "target_tilt_x_deg", 1.0)
    assert wait_until(ros_context,
        lambda: np.max(np.abs(recent_mean() - level)) > 1.0, HANG_GUARD_S), (
            level, recent_mean())
    _check_rejected(client, "target_tilt_x_deg", [2.6, -3.0, math.nan, "1"])
    _check_accepted(client, "target_tilt_x_deg", 2.0)
    _check_rejected(client, "target_tilt_y_deg", [2.0, -1.6], "tilt", "2.5")   # norm > 2.5
    _check_accepted(client, "target_tilt_y_deg", 1.0)
    _check_rejected(client, "target_tilt_x_deg", [2.4], "tilt")
    _check_accepted(client, "target_tilt_x_deg", 0.0)
    _check_accepted(client, "target_tilt_y_deg", 0.0)
    _check_rejected(client, "target_twist_deg", [10.5, -11.0, math.inf])
    _check_accepted(client, "target_twist_deg", 5.0)
    _check_accepted(client, "target_twist_deg", 0.0)
    _check_rejected(client, "target_translation_m", [[0.0, 0.0], [0.0, 0.0, 0.0, 0.0]], "3")
    _check_rejected(client, "target_translation_m", [[2e-3, 0.0, 0.0], [0.0, math.nan, 0.0]])
    _check_rejected(client, "target_translation_m",
                    [Parameter("target_translation_m", Parameter.Type.DOUBLE_ARRAY, [])], "3")
    _check_accepted(client, "target_translation_m", [1e-4, 0.0, 0.0])
    for name, good, bad in (("bandwidth_hz", 2.0, [0.0, 10.0, math.nan]),
                            ("damping_ratio", 0.5, [0.0, 3.0]),
                            ("output_lowpass_hz", 20.0, [1.0, 200.0])):
        _check_accepted(client, name, good)
        _check_rejected(client, name, bad)

    # Disabled: exactly zero force.
    _check_accepted(client, "enabled", False)
    mark = command.last_index
    assert wait_until(ros_context,
        lambda: command.last_index > mark + 200
        and not np.any(command.window(command.last_index - 100, command.last_index + 1)[1]),
        HANG_GUARD_S)
    _check_accepted(client, "enabled", True)
    _check_read_only(client, {"model_file": "/tmp/model.yaml", "executor": "events"})
    assert pointing.running() and driver.running()


def _refused_at_start_up(process) -> str:
    """The one error line of a node that refused its start-up parameters (exit 2)."""
    code = process.wait(HANG_GUARD_S)
    assert code == 2, process.output()
    lines = process.stderr_path.read_text().strip().splitlines()
    errors = [line for line in lines if line.startswith("notch_controller: error: ")]
    assert len(errors) == 1 and "Traceback" not in process.output(), process.output()
    return errors[0]


def test_notch_settings_that_cannot_work_are_refused_on_every_route(ros_context,
                                                                    node_processes,
                                                                    tmp_path):
    """``-p``, a params file and ``ros2 param set`` refuse them with the same reason.

    Tracking needs the broadband identification, and so does ``mu_policy: auto`` (the
    default); the paper's preset (``config/presets/paper.yaml``) is a params file the node
    takes as it is. (The scenario route: test/core/test_notch_settings.py.)
    """
    auto = "mu_policy auto needs identification: broadband"
    tracking = "frequency_tracking needs identification: broadband"
    line = _refused_at_start_up(node_processes.start(
        "notch_controller", "--ros-args", "-p", "identification:=tones"))
    assert auto in line, line
    params = tmp_path / "tracked_tones.yaml"
    params.write_text(yaml.safe_dump({"notch_controller": {"ros__parameters": {
        "mu_policy": "manual", "identification": "tones", "frequency_tracking": True}}}))
    line = _refused_at_start_up(node_processes.start(
        "notch_controller", "--ros-args", "--params-file", str(params)))
    assert tracking in line, line

    preset = ROOT / "config" / "presets" / "paper.yaml"
    paper = yaml.safe_load(preset.read_text())["notch_controller"]["ros__parameters"]
    process = node_processes.start("notch_controller", "--ros-args", "--params-file",
                                   str(preset))
    node = ros_context.create_node("param_client")
    client = ParameterClient(ros_context, node, "notch_controller")
    assert client.get(*paper) == paper
    _check_rejected(client, "frequency_tracking", [True], tracking)
    _check_accepted(client, "identification", "broadband")
    _check_accepted(client, "frequency_tracking", True)      # the paper's update: explicit
    _check_rejected(client, "identification", ["tones"], tracking)
    assert process.stop() == 130, process.output()          # one notch_controller at a time

    # At the defaults the update low-pass is automatic, chosen at start-up for fixed tones:
    # tracking switched on later is refused with the reason (at start-up it is taken).
    node_processes.start("notch_controller")
    client = ParameterClient(ros_context, node, "notch_controller")
    _check_rejected(client, "identification", ["tones"], auto, "mu_policy manual first")
    _check_rejected(client, "frequency_tracking", [True], "chosen at start-up",
                    "start the node with frequency_tracking set so")
    _check_accepted(client, "mu_policy", "manual")
    _check_accepted(client, "identification", "tones")
