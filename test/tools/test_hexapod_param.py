"""``hexapod_param``: a running node's parameters without the ``ros2`` CLI.

Against a real node process (the pointing controller, which needs no driver to answer its
parameter services): list, get, set (typed as ``ros2 param set`` types it, fitted to the
declared type), a refused value (exit 1, the node's reason, nothing changed), an unknown
parameter, dump and load, a node that is not there (exit 3), Ctrl-C while waiting (130).
The command line is checked before rclpy is imported (exit 2, one line).
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from rcl_interfaces.msg import ParameterType

from hexapod_vibration.parameter_specs import POINTING_CONTROLLER
from hexapod_vibration.tools.parameter_services import fit_value

BIN = Path(sys.executable).parent
HANG_GUARD_S = 120.0
NODE = "/pointing_controller"


def param(*args: str, env=None) -> subprocess.CompletedProcess:
    """Run ``hexapod_param ARGS`` under ``-X importtime`` (imported modules in stderr)."""
    result = subprocess.run([sys.executable, "-X", "importtime", str(BIN / "hexapod_param"),
                             *args], env=env, capture_output=True, text=True,
                            timeout=HANG_GUARD_S, stdin=subprocess.DEVNULL)
    result.imported = set(re.findall(r"import time:\s+\d+ \|\s+\d+ \|\s*(\w+)", result.stderr))
    result.stderr = "\n".join(line for line in result.stderr.splitlines()
                              if not line.startswith("import time:"))
    return result


def error_line(result: subprocess.CompletedProcess, code: int) -> str:
    """The one ``hexapod_param...: error:`` line of a failed run with exit ``code``."""
    assert result.returncode == code, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and re.match(r"hexapod_param( \w+)?: error: ", lines[0]), lines
    assert "Traceback" not in result.stderr
    return lines[0]


@pytest.mark.parametrize(("value", "declared", "text", "expected"), [
    (1, ParameterType.PARAMETER_DOUBLE, "1", 1.0),
    ("1e-3", ParameterType.PARAMETER_DOUBLE, "1e-3", 0.001),
    (True, ParameterType.PARAMETER_DOUBLE, "true", True),          # not a number: as given
    ([1, "2.5", 3.0], ParameterType.PARAMETER_DOUBLE_ARRAY, None, [1.0, 2.5, 3.0]),
    ([1, "a"], ParameterType.PARAMETER_DOUBLE_ARRAY, None, [1, "a"]),
    ([], ParameterType.PARAMETER_STRING_ARRAY, "[]", []),
    (12, ParameterType.PARAMETER_STRING, "12", "12"),
    ("lockstep", ParameterType.PARAMETER_STRING, "lockstep", "lockstep"),
    (3, ParameterType.PARAMETER_INTEGER, "3", 3),
])
def test_values_are_fitted_to_the_declared_type_where_the_meaning_is_plain(
        value, declared, text, expected):
    fitted = fit_value(value, declared, text)
    assert fitted == expected and type(fitted) is type(expected)


def test_a_bad_command_line_is_one_line_and_exit_2_before_rclpy(tmp_path):
    for args, words in ((["set", NODE, "mu"], "required"), (["get", "bad name", "mu"], "node"),
                        (["--timeout", "-1", "list", NODE], "--timeout"),
                        (["frobnicate", NODE], "invalid choice"),
                        (["load", NODE, str(tmp_path / "missing.yaml")], "does not exist")):
        result = param(*args)
        assert words in error_line(result, 2), args
        assert "rclpy" not in result.imported, args
    not_params = tmp_path / "list.yaml"
    not_params.write_text("- 1\n")
    assert "no parameters for /pointing_controller" in error_line(
        param("load", NODE, str(not_params)), 2)


def test_a_node_that_does_not_answer_is_exit_3(ros_env):
    line = error_line(param("--timeout", "1", "get", "/no_such_node", "mu", env=ros_env), 3)
    assert "/no_such_node" in line and f"ROS_DOMAIN_ID={ros_env['ROS_DOMAIN_ID']}" in line


def test_ctrl_c_while_waiting_exits_130_quietly(ros_env):
    process = subprocess.Popen([str(BIN / "hexapod_param"), "--timeout", "60", "list",
                                "/no_such_node"], env=ros_env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)                         # inside the wait for the services (or before)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=HANG_GUARD_S)
    assert process.returncode == 130, (out, err)
    assert "Traceback" not in err, err


def test_list_get_set_refuse_dump_and_load_on_a_real_node(node_processes, tmp_path):
    node = node_processes.start("pointing_controller")
    env = node_processes.env
    names = param("--timeout", "60", "list", NODE, env=env)
    assert names.returncode == 0, (names.stderr, node.output())
    assert {"target_tilt_x_deg", "bandwidth_hz", "target_translation_m"} <= set(
        names.stdout.split())
    before = param("dump", NODE, env=env)
    assert before.returncode == 0, before.stderr
    dump = tmp_path / "pointing.yaml"
    dump.write_text(before.stdout)
    assert yaml.safe_load(before.stdout)[NODE]["ros__parameters"]["target_tilt_x_deg"] == 0.0

    # Set, typed as ros2 param set types it, then fitted: an integer for a double.
    result = param("set", NODE, "target_tilt_x_deg", "1", env=env)
    assert result.returncode == 0 and result.stdout == f"{NODE}: target_tilt_x_deg = 1.0\n", (
        result.stdout, result.stderr)
    result = param("set", NODE, "target_translation_m", "[0, 0, 1e-4]", env=env)
    assert result.returncode == 0, result.stderr
    got = param("get", NODE, "target_tilt_x_deg", "target_translation_m", env=env)
    assert got.stdout.splitlines() == ["target_tilt_x_deg: 1.0",
                                       "target_translation_m: [0.0, 0.0, 0.0001]"]

    # Refused: the node's own reason, exit 1, nothing changed.
    line = error_line(param("set", NODE, "target_twist_deg", "12.0", env=env), 1)
    assert line.startswith(f"hexapod_param: error: {NODE} refused target_twist_deg = 12.0: ")
    assert "target_twist_deg" in line.split(": ", 3)[3]
    line = error_line(param("set", NODE, "target_translation_m", "[]", env=env), 1)
    assert "3 values" in line
    line = error_line(param("set", NODE, "executor", "events", env=env), 1)
    assert "read-only" in line
    line = error_line(param("get", NODE, "target_twst_deg", env=env), 1)
    assert "no parameter 'target_twst_deg'" in line and "did you mean target_twist_deg" in line
    assert param("get", NODE, "target_twist_deg", env=env).stdout == "target_twist_deg: 0.0\n"

    # load: the dump back (read-only ones skipped), every value as it was.
    result = param("load", NODE, str(dump), env=env)
    assert result.returncode == 0, (result.stdout, result.stderr)
    skipped = result.stdout.split("skipped read-only: ")[1].strip().split(", ")
    assert set(skipped) == {p.name for p in POINTING_CONTROLLER.parameters if p.read_only} | {
        "start_type_description_service"}, result.stdout
    assert param("dump", NODE, env=env).stdout == before.stdout
    assert node.running(), node.output()
