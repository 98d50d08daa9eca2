"""Shared test infrastructure: the test tiers, isolated ROS domains, node processes, rclpy.

**Tiers** (markers registered in ``setup.cfg``, ``--strict-markers``), given here, not in
the test files, so that a test lands in its tier wherever it is moved:

- ``graph``: the test uses a ROS fixture (:data:`ROS_FIXTURES`: it starts node processes,
  an rclpy context, or console scripts on its own ROS domain); also marked ``ros``, the
  older name of the same set;
- ``scenario``: a long run of the core closed loop (a shipped scenario, often with its
  twin), listed in :data:`SCENARIO_TESTS` by file name or ``file::test`` name;
- ``unit``: every other test. ``make check`` runs ``-m unit``, ``make test`` all three.

A test is in exactly one tier. When the whole suite is collected, a name in
:data:`SCENARIO_TESTS` that matches no test stops the run (a renamed or moved test must
not fall silently into ``unit``).

Every test that uses ROS gets its own ``ROS_DOMAIN_ID`` (a per-run random base, or
``HEXAPOD_TEST_DOMAIN_BASE``, plus a per-test counter), with discovery limited to this
machine, so that tests and concurrent runs never see each other's nodes. rclpy is imported
only by the ``ros_context`` fixture (``test/ros_test_context.py``).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import random
import signal
import sys
from collections.abc import Iterator
from pathlib import Path

import forked_nodes
import pytest

from hexapod_vibration.tools import processes

DOMAIN_MIN = 20
DOMAIN_LIMIT = 230  # exclusive; Fast DDS port arithmetic allows up to 232
_domain_base = int(os.environ.get("HEXAPOD_TEST_DOMAIN_BASE") or random.randint(DOMAIN_MIN, 200))
_domain_counter = itertools.count()

ROS_FIXTURES = frozenset({"ros_env", "node_processes", "ros_context"})
"""Fixtures that put a test on a ROS domain: such a test is in the ``graph`` tier."""

TEST_DIR = Path(__file__).resolve().parent
BIN_DIR = Path(sys.executable).parent
"""Folder of the virtualenv's console scripts (pph_recorder, ...)."""

SCENARIO_TESTS = (
    "test_never_worse_core_loop.py", "test_sensitivity_core_loop.py", "test_harmonic_rise.py",
    "test_tracking_range_core_loop.py", "test_notch_settings_at_any_moment.py",
    "test_closed_loop.py::test_table1_reduces_40hz_by_60db_and_80hz_by_40db",
    "test_closed_loop.py::test_table2_close_tones_each_reduced_by_55db",
    "test_fxlms.py::test_bench_quick_writes_positive_finite_numbers",
)
"""The ``scenario`` tier: core closed-loop runs of a shipped scenario, 30-240 s each on a
quiet 2-core machine, and the notch's settings changed at every moment of its sequence
(~1 s of Nyquist tests per case; 22 s) (a file name: all its tests; ``file::test``: that
test, every parametrization)."""

LONG_FIRST = ("test_moving_tones_graph.py", "test_experiment.py", "test_twin_graph.py",
              "test_sensitivity_core_loop.py", "test_params_file.py", "test_fxlms.py",
              "test_colcon_layout.py", "test_never_worse_core_loop.py",
              "test_tracking_range_core_loop.py", "test_harmonic_rise.py")
"""Files of the longest tests, collected first so that pytest-xdist's workers do not end on
them one after the other (order only: none depends on another)."""


def _scenario_entry(item: pytest.Item) -> str | None:
    """The :data:`SCENARIO_TESTS` entry that names ``item``, or None."""
    name = getattr(item, "originalname", item.name)
    for entry in (item.path.name, f"{item.path.name}::{name}"):
        if entry in SCENARIO_TESTS:
            return entry
    return None


def _tier(item: pytest.Item) -> str:
    """``graph``, ``scenario`` or ``unit`` (see the module docstring)."""
    uses_ros = bool(ROS_FIXTURES.intersection(getattr(item, "fixturenames", ())))
    scenario = _scenario_entry(item) is not None
    if uses_ros and scenario:
        raise pytest.UsageError(f"{item.nodeid} is listed in SCENARIO_TESTS (test/conftest.py) "
                                "but uses a ROS fixture: it is a graph test")
    return "graph" if uses_ros else "scenario" if scenario else "unit"


def _whole_suite(config: pytest.Config) -> bool:
    """Whether this run collects every test (``pytest test``, ``make test``/``check``)."""
    paths = [(config.invocation_params.dir / arg).resolve() for arg in config.args]
    return paths == [TEST_DIR]


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Remove the Fast DDS shared-memory files the run's killed nodes left (``fastdds shm clean``).

    Tests SIGKILL nodes on purpose; a killed participant leaves its segments and port files
    in /dev/shm (about 300 files, 25 MB, a run). Fast DDS's own tool removes those whose lock
    no live process holds, so a concurrent run's are kept. Once, at the end of the whole
    run (the xdist controller); skipped where the tool is not installed.
    """
    if hasattr(session.config, "workerinput"):
        return
    import shutil
    import subprocess

    tool = BIN_DIR / "fastdds" if (BIN_DIR / "fastdds").exists() else shutil.which("fastdds")
    if tool is not None:
        with contextlib.suppress(OSError, subprocess.SubprocessError):
            subprocess.run([str(tool), "shm", "clean"], capture_output=True, timeout=60,
                           check=False)


@pytest.hookimpl(tryfirst=True)     # before -m deselects anything
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Give every test its tier marker (and ``ros`` to graph tests); the longest files first."""
    for item in items:
        tier = _tier(item)
        item.add_marker(tier)
        if tier == "graph":
            item.add_marker(pytest.mark.ros)
    if _whole_suite(config):
        used = {_scenario_entry(item) for item in items}
        stale = [entry for entry in SCENARIO_TESTS if entry not in used]
        if stale:
            raise pytest.UsageError(f'SCENARIO_TESTS in test/conftest.py names no test: '
                                    f'{", ".join(stale)} (renamed or moved? update the list)')
    rank = {name: k for k, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FIRST)))    # stable


def _worker() -> tuple[int, int]:
    """(this pytest-xdist worker's number, the number of workers); (0, 1) without xdist."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return int(name.removeprefix("gw") or 0), int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", 1))


def next_domain_id() -> int:
    """A ROS domain id not used before in this test session, in [DOMAIN_MIN, DOMAIN_LIMIT).

    With pytest-xdist, worker k of W takes the ids congruent to k modulo W, so that
    parallel workers never share a domain.
    """
    worker, workers = _worker()
    span = (DOMAIN_LIMIT - DOMAIN_MIN) // workers * workers
    return DOMAIN_MIN + (_domain_base - DOMAIN_MIN + workers * next(_domain_counter)
                         + worker) % span


# UDP only where it takes effect: the tests SIGKILL nodes on purpose, which leaves Fast
# DDS shared-memory port files locked in /dev/shm, and a later participant can then pick
# a dead shared-memory channel and silently receive nothing (seen: a controller that never
# got /pph/accel). Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (``ros_env``) rmw_fastrtps
# replaces the built-in transports with its own shared-memory + UDP pair, so the graph
# tests' nodes still open shared-memory ports (their threads dds.shm.*: seen 2026-12-05;
# hexapod_vibration.ros.dds_transport).
os.environ.setdefault("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4")


@pytest.fixture
def ros_env() -> dict[str, str]:
    """Environment for ROS processes of one test: own domain, localhost discovery only."""
    env = dict(os.environ)
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated; conflicts with the discovery range
    env.update(
        ROS_DOMAIN_ID=str(next_domain_id()),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
        PYTHONUNBUFFERED="1",
    )
    return env


class NodeProcess:
    """A console script of the package run as a separate process, output kept in files.

    Forked from a warm process that imported rclpy, numpy and scipy once
    (``test/forked_nodes.py``; ``HEXAPOD_TEST_FORK=0``, or a ``command``: started with
    ``hexapod_vibration.tools.processes.spawn``): own session (signals from the terminal go
    to pytest only) and a parent-death signal (it dies with pytest, even when pytest is
    killed).
    """

    def __init__(self, executable: str, args: list[str], env: dict[str, str], log_dir: Path,
                 cwd: Path | None = None, command: list[str] | None = None):
        """Start ``BIN_DIR/executable args`` (or ``command``) with ``env``, logs in ``log_dir``."""
        self.name = executable
        self.stdout_path = log_dir / f"{executable}.{id(self)}.stdout"
        self.stderr_path = log_dir / f"{executable}.{id(self)}.stderr"
        argv = command or [str(BIN_DIR / executable), *args]
        if command is None and forked_nodes.enabled():
            self.child = forked_nodes.start(executable, argv, env, cwd, self.stdout_path,
                                            self.stderr_path)
        else:
            self.child = processes.spawn(executable, argv, log=self.stdout_path,
                                         stderr_log=self.stderr_path, env=env, cwd=cwd)
        self.process = self.child.process

    @property
    def pid(self) -> int:
        """Process id."""
        return self.process.pid

    def running(self) -> bool:
        """Whether the process is still alive."""
        return self.child.alive()

    def wait(self, timeout_s: float) -> int | None:
        """Wait for the process to exit on its own; its exit code, or None on timeout."""
        return self.child.wait(timeout_s)

    def stop(self, timeout_s: float = 20.0) -> int:
        """SIGINT, wait up to ``timeout_s``, then SIGKILL (its group); returns the exit code."""
        return self.child.stop(timeout_s)

    def output(self) -> str:
        """Everything the process wrote so far, stdout then stderr."""
        out = self.stdout_path.read_text(errors="replace")
        err = self.stderr_path.read_text(errors="replace")
        return f"--- {self.name} stdout ---\n{out}--- {self.name} stderr ---\n{err}"


class NodeProcesses:
    """Starts node processes for one test and stops every one of them at teardown."""

    def __init__(self, env: dict[str, str], log_dir: Path):
        """Processes get ``env`` (the test's ROS domain) and log into ``log_dir``."""
        self.env = env
        self.log_dir = log_dir
        self.started: list[NodeProcess] = []

    def start(self, executable: str, *args: str, env: dict[str, str] | None = None,
              cwd: Path | None = None, command: list[str] | None = None) -> NodeProcess:
        """Start a console script of the virtualenv with ``args`` (or any ``command``)."""
        process = NodeProcess(executable, list(args), env or self.env, self.log_dir, cwd,
                              command)
        self.started.append(process)
        return process

    def stop_all(self) -> None:
        """Stop every process still running: SIGINT to all at once, then SIGKILL stragglers.

        At once, not in turn: each node's exit (its teardown, a driver's flush to its
        readers) then overlaps the others' (a test's teardown took up to 2.8 s in turn).
        """
        for process in self.started:
            process.child.send(signal.SIGINT)         # only if it still runs
        for process in self.started:
            if process.child.wait(10.0) is None:
                process.child.kill()
            process.child.close_logs()


@pytest.fixture
def node_processes(ros_env: dict[str, str], tmp_path: Path) -> Iterator[NodeProcesses]:
    """Factory of :class:`NodeProcess` on the test's domain; none survives the test."""
    processes = NodeProcesses(ros_env, tmp_path)
    try:
        yield processes
    finally:
        processes.stop_all()


@pytest.fixture
def ros_context(ros_env: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> Iterator:
    """An in-test rclpy context (``RosTestContext``) on the domain of the test's nodes."""
    from ros_test_context import RosTestContext  # rclpy only for the tests that use it

    for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "RMW_IMPLEMENTATION"):
        monkeypatch.setenv(key, ros_env[key])
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    context = RosTestContext(int(ros_env["ROS_DOMAIN_ID"]))
    try:
        yield context
    finally:
        context.shutdown()
