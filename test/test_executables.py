"""Every console script of setup.py: --help, bad arguments, and no heavy import before them.

Each executable is run as a user runs it (the virtualenv's console script), under
``python -X importtime`` so that the modules it imported are known: ``--help`` and a bad
argument must be answered before rclpy, numpy, scipy, matplotlib or rosbags are imported
(which is what makes them quick, and proves no work was started). Nothing here is timed;
the subprocess timeout is a hang guard (the old ``pph_driver --help`` started the driver).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
HEAVY = ("rclpy", "numpy", "scipy", "matplotlib", "rosbags")
HANG_GUARD_S = 120.0


def console_scripts() -> dict[str, str]:
    """``name: module:function`` of every console script declared in setup.py."""
    text = (ROOT / "setup.py").read_text()
    return dict(re.findall(r"[\"'](\w+) = ([\w.]+:\w+)[\"']", text))


NODES = ("pph_driver", "notch_controller", "pointing_controller", "pph_graph", "pph_recorder")


def run_script(name: str, *args: str, env=None, cwd=None) -> tuple[subprocess.CompletedProcess,
                                                                     set[str]]:
    """Run a console script with -X importtime; (result, top-level packages imported)."""
    try:
        result = subprocess.run([sys.executable, "-X", "importtime", str(BIN / name), *args],
                                capture_output=True, text=True, timeout=HANG_GUARD_S, env=env,
                                cwd=cwd, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f'{name} {" ".join(args)} did not return: it started working'
                             ) from exc
    imported = set(re.findall(r"import time:\s+\d+ \|\s+\d+ \|\s*([\w]+)", result.stderr))
    result.stderr = "\n".join(line for line in result.stderr.splitlines()
                              if not line.startswith("import time:"))
    return result, imported


def test_setup_declares_every_executable():
    assert set(NODES) | {"experiment", "analyze", "hexapod_bench", "soak", "sweep"} <= set(
        console_scripts())


@pytest.mark.parametrize("name", sorted(console_scripts()))
def test_help_prints_usage_and_imports_nothing_heavy(name, ros_env, tmp_path):
    result, imported = run_script(name, "--help", env=ros_env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.lower().startswith("usage:"), result.stdout[:500]
    assert name in result.stdout
    assert not imported & set(HEAVY), sorted(imported & set(HEAVY))
    assert not list(tmp_path.iterdir()), "it wrote something"


def test_node_help_lists_every_parameter_of_its_spec(ros_env):
    from hexapod_vibration.parameter_specs import NODE_SPECS

    graph, _ = run_script("pph_graph", "-h", env=ros_env)
    for node in ("pph_driver", "notch_controller", "pointing_controller"):
        text, _ = run_script(node, "--help", env=ros_env)
        for parameter in NODE_SPECS[node].names:
            assert f"    {parameter}" in text.stdout, (node, parameter)
            assert f"    {parameter}" in graph.stdout, (node, parameter)


def one_line_error(result: subprocess.CompletedProcess, name: str, *words: str) -> None:
    """Exit 2 and exactly one line on stderr: ``name: error: ...`` with ``words``."""
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"{name}: error:"), lines[0]
    for word in words:
        assert word in lines[0], lines[0]
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("name", NODES)
def test_node_arguments_are_checked_before_ros_starts(name, ros_env, tmp_path):
    result, imported = run_script(name, "--duration", "5", env=ros_env)
    one_line_error(result, name, "unrecognized arguments: --duration 5")
    assert "rclpy" not in imported
    result, imported = run_script(name, "--ros-args", "--params-file",
                                  str(tmp_path / "missing.yaml"), env=ros_env)
    one_line_error(result, name, "--params-file", "missing.yaml", "does not exist")
    assert "rclpy" not in imported
    bad = tmp_path / "bad.yaml"
    bad.write_text("just a string\n")
    result, _ = run_script(name, "--ros-args", "--params-file", str(bad), env=ros_env)
    one_line_error(result, name, "--params-file", "not a ROS params file")


def test_tool_arguments_are_checked_before_any_work(ros_env, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    bag = tmp_path / "bag"
    bag.mkdir()
    cases = [
        ("experiment", ["--scenario", "close_tones", "--out", str(a_file)], "--out"),
        ("experiment", ["--scenario", "close_tones", "--out", str(a_file / "sub")], "--out"),
        ("experiment", ["--scenario", "close_tones", "--out", str(tmp_path / "o"),
                        "--duration", "1e9"], "--duration"),
        ("experiment", ["--scenario", "close_tones", "--out", str(tmp_path / "o"),
                        "--duration", "-5"], "--duration"),
        ("experiment", ["--scenario", "close_tones", "--out", str(tmp_path / "o"),
                        "--duration", "nan"], "--duration"),
        ("experiment", ["--scenario", "close_tones", "--out", str(tmp_path / "o"),
                        "--control-on", "inf"], "--control-on"),
        ("experiment", ["--out", str(tmp_path / "o")], "--scenario"),
        ("analyze", [str(bag), "--out", str(a_file)], "--out"),
        ("analyze", [str(bag), "--out", str(tmp_path / "o"), "--window", "nan"], "--window"),
        ("analyze", [str(bag), "--out", str(tmp_path / "o"), "--window", "-5"], "--window"),
        ("analyze", [str(bag), "--out", str(tmp_path / "o"), "--tones", "600"], "--tones"),
        ("analyze", [str(tmp_path / "no_bag"), "--out", str(tmp_path / "o")], "bag"),
        ("hexapod_bench", ["--out", str(a_file)], "--out"),
        ("soak", ["--duration", "-5"], "--duration"),
        ("soak", ["--out", str(a_file)], "--out"),
    ]
    for name, args, argument in cases:
        result, imported = run_script(name, *args, env=ros_env, cwd=tmp_path)
        try:
            one_line_error(result, name, argument)
        except AssertionError as exc:
            raise AssertionError(f"{name} {args}: {exc}") from None
        assert not imported & {"rclpy", "scipy", "matplotlib"}, (name, args)
    assert not (tmp_path / "o").exists()


def test_experiment_refuses_a_scenario_that_does_not_fit_the_arguments(ros_env, tmp_path):
    result, _ = run_script("experiment", "--scenario", "close_tones", "--out",
                           str(tmp_path / "o"), "--control-on", "50", env=ros_env)
    one_line_error(result, "experiment", "--control-on")
    result, _ = run_script("experiment", "--scenario", "no_such", "--out", str(tmp_path / "o"),
                           env=ros_env)
    one_line_error(result, "experiment", "single_tone_harmonic")
    assert not (tmp_path / "o").exists()
