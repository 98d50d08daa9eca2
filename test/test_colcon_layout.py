"""Every README command, as a colcon user runs it: ``ros2 run`` forms, share-directory paths.

The package is installed the way colcon's ament_python build does it (``setup.py install``
with ``setup.cfg``'s ``install_scripts``: entry points in ``install/lib/hexapod_vibration``,
data in ``install/share/hexapod_vibration``, the ament index entry), and every command of
the README's code blocks is checked against that tree from a folder outside the source:

- ``ros2 run hexapod_vibration EXE ARGS`` runs ``install/lib/hexapod_vibration/EXE ARGS``
  with ``$(ros2 pkg prefix --share hexapod_vibration)`` expanded and ``/tmp/...`` moved
  into the test's folder: a node must come up and exit 130 on SIGINT, ``--help`` must exit
  0, ``analyze`` must write its report, ``experiment`` must find its scenario;
- ``ros2 launch hexapod_vibration FILE ARGS`` names an installed launch file and only the
  launch arguments it declares, with allowed values (launch itself is not installed here);
- no command calls a package executable bare (``analyze <bag>`` is not on a colcon
  user's PATH) or a source-relative ``config/`` path.
"""

from __future__ import annotations

import ast
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_executables import console_scripts

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "hexapod_vibration"
SHARE_EXPR = f"$(ros2 pkg prefix --share {PACKAGE})"
SHARE = "@SHARE@"
"""What the commands hold in place of SHARE_EXPR (one shell word)."""
HANG_GUARD_S = 120.0
NODES = {"pph_driver": ["PPH driver up"], "notch_controller": ["notch controller up"],
         "pointing_controller": ["pointing controller up"], "pph_recorder": ["recording"],
         "pph_graph": ["PPH driver up", "notch controller up", "pointing controller up"]}


def readme_commands() -> list[str]:
    """Every command line of the README's bash blocks (continuations joined)."""
    text = (ROOT / "README.md").read_text()
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.strip()
            if line and not line.startswith("#"):
                commands.append(line.replace(SHARE_EXPR, SHARE))
    return commands


@pytest.fixture(scope="module")
def install(tmp_path_factory) -> Path:
    """A colcon-style install of the package (``install/``), built from the source tree."""
    base = tmp_path_factory.mktemp("colcon")
    (base / "egg").mkdir()
    result = subprocess.run(
        [sys.executable, "setup.py", "-q", "egg_info", "--egg-base", str(base / "egg"),
         "build", "--build-base", str(base / "build"), "install", "--prefix",
         str(base / "install"), "--single-version-externally-managed", "--record",
         str(base / "record.txt")], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    return base / "install"


@pytest.fixture
def colcon_env(install, ros_env) -> dict[str, str]:
    """``source install/setup.bash``, as far as this package needs it."""
    site = next((install / "lib").glob("python3*/site-packages"))
    return dict(ros_env, AMENT_PREFIX_PATH=str(install), PYTHONPATH=str(site),
                PATH=f'{install / "lib" / PACKAGE}{os.pathsep}{ros_env["PATH"]}')


def localise(words: list[str], install: Path, tmp: Path) -> list[str]:
    share = str(install / "share" / PACKAGE)
    return [w.replace("/tmp/", f"{tmp}/").replace(SHARE, share) for w in words]


def test_the_install_is_the_colcon_layout(install):
    for name in console_scripts():
        assert (install / "lib" / PACKAGE / name).is_file(), name
    share = install / "share" / PACKAGE
    for path in ("package.xml", "config/pph.yaml", "config/pph_model.yaml",
                 "config/fastdds_profiles.xml", "config/scenarios/single_tone_harmonic.yaml",
                 "launch/pph.launch.py"):
        assert (share / path).is_file(), path
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()


def test_readme_commands_use_the_colcon_forms():
    scripts = console_scripts()
    commands = readme_commands()
    assert any(c.startswith(f"ros2 run {PACKAGE} ") for c in commands)
    for command in commands:
        words = shlex.split(command, comments=True)
        if not words:
            continue
        assert words[0] not in scripts, f"not on a colcon PATH, use ros2 run: {command}"
        if words[:2] == ["ros2", "run"]:
            assert words[2] == PACKAGE and words[3] in scripts, command
        if words[0].startswith(".venv/"):
            continue            # the virtualenv route runs in the source tree (test_readme.py)
        for word in words:
            if "config/" in word and not word.startswith(SHARE):
                raise AssertionError(f"source-relative path in: {command}")


def launch_arguments() -> dict[str, list[str] | None]:
    """Declared launch arguments of launch/pph.launch.py and their choices (None: any)."""
    tree = ast.parse((ROOT / "launch" / "pph.launch.py").read_text())
    declared = {}
    for call in ast.walk(tree):
        if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "DeclareLaunchArgument":
            choices = next((ast.literal_eval(k.value) for k in call.keywords
                            if k.arg == "choices"), None)
            declared[call.args[0].value] = choices
    return declared


def test_readme_launch_commands_name_declared_arguments(install):
    declared = launch_arguments()
    for command in readme_commands():
        words = shlex.split(command, comments=True)
        if words[:2] != ["ros2", "launch"]:
            continue
        assert words[2] == PACKAGE, command
        assert (install / "share" / PACKAGE / "launch" / words[3]).is_file(), command
        for argument in words[4:]:
            name, value = argument.split(":=", 1)
            assert name in declared, (command, name)
            assert declared[name] is None or value in declared[name], (command, argument)


def run_node(words, env, cwd, expected, log: Path):
    """Start a node command, wait until its log shows it up, SIGINT it: exit 130, quiet."""
    with log.open("wb") as stream:
        process = subprocess.Popen(words, env=env, cwd=cwd, stdout=stream,
                                   stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + HANG_GUARD_S
    try:
        while not all(line in log.read_text() for line in expected):
            assert process.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)
        process.send_signal(2)
        assert process.wait(HANG_GUARD_S) == 130, log.read_text()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert "Traceback" not in log.read_text(), log.read_text()


def test_readme_ros2_run_commands_work_from_another_folder(install, colcon_env, tmp_path):
    from hexapod_vibration.analysis.bag_writer import write_strut_bag

    work = tmp_path / "elsewhere"
    work.mkdir()
    ran = set()
    for command in readme_commands():
        words = shlex.split(command, comments=True)
        if words[:3] != ["ros2", "run", PACKAGE]:
            continue
        exe, args = words[3], localise(words[4:], install, tmp_path)
        path = str(install / "lib" / PACKAGE / exe)
        if "--help" in args:
            result = subprocess.run([path, *args], env=colcon_env, cwd=work,
                                    capture_output=True, text=True, timeout=HANG_GUARD_S)
            assert result.returncode == 0 and "usage" in result.stdout, command
        elif exe in NODES:
            run_node([path, *args], colcon_env, work, NODES[exe], tmp_path / f"{exe}.log")
        elif exe == "analyze":
            n = 12_000
            accel = 9.8 + 0.1 * np.sin(2 * np.pi * 40.0 * np.arange(n) / 1000.0)
            if args[0] == "<bag>":                     # the README's placeholder
                args[0] = str(tmp_path / f"bag{len(ran)}")
            bag = Path(args[0])
            write_strut_bag(bag, {"/pph/accel": (np.arange(n), np.tile(accel[:, None], 6))})
            result = subprocess.run([path, *args, "--no-plots"], env=colcon_env, cwd=work,
                                    capture_output=True, text=True, timeout=HANG_GUARD_S)
            assert result.returncode == 0, result.stderr
            assert (Path(args[args.index("--out") + 1]) / "report.json").is_file()
        elif exe == "experiment":
            # The whole run takes minutes: check that it finds its scenario in the share
            # directory and checks its output, up to the refusal of an existing bag.
            out = Path(args[args.index("--out") + 1])
            (out / "bag").mkdir(parents=True)
            result = subprocess.run([path, *args], env=colcon_env, cwd=work,
                                    capture_output=True, text=True, timeout=HANG_GUARD_S)
            assert result.returncode == 2 and "exists" in result.stderr, result.stderr
            (out / "bag").rmdir()
        elif exe == "sweep":
            # A dry run: the grid is found (shipped by name in the share directory, or the
            # user's file) and checked, the points listed, nothing run (no cluster needed).
            if args[0] == "my_grid.yaml":             # the README's placeholder
                grid = tmp_path / "my_grid.yaml"
                grid.write_text((install / "share" / PACKAGE / "config" / "sweeps" /
                                 "mu_bound.yaml").read_text())
                args[0] = str(grid)
            out = args.index("--out") + 1
            args[out] = str(tmp_path / "sweeps" / Path(args[out]).name)
            result = subprocess.run([path, *args, "--dry-run"], env=colcon_env, cwd=work,
                                    capture_output=True, text=True, timeout=HANG_GUARD_S)
            assert result.returncode == 0 and "points" in result.stdout, (command,
                                                                         result.stderr)
        else:
            raise AssertionError(f"no check for {command}")
        ran.add(exe)
    assert {"pph_graph", "pph_driver", "analyze", "experiment"} <= ran
    assert not list(work.iterdir()), "a command wrote into the current folder"
