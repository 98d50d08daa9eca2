"""Shared test infrastructure: isolated ROS domains, node processes, an in-test rclpy context.

Every test that uses ROS gets its own ``ROS_DOMAIN_ID`` (a per-run random base, or
``HEXAPOD_TEST_DOMAIN_BASE``, plus a per-test counter), with discovery limited to this
machine, so that tests and concurrent runs never see each other's nodes.
"""

from __future__ import annotations

import itertools
import os
import random
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from hexapod_vibration.tools import processes

DOMAIN_MIN = 20
DOMAIN_LIMIT = 230  # exclusive; Fast DDS port arithmetic allows up to 232
_domain_base = int(os.environ.get('HEXAPOD_TEST_DOMAIN_BASE') or random.randint(DOMAIN_MIN, 200))
_domain_counter = itertools.count()

ROS_FIXTURES = frozenset({'ros_env', 'node_processes', 'ros_context'})
"""Fixtures that put a test on a ROS domain: such a test is marked ``ros``."""

BIN_DIR = Path(sys.executable).parent
"""Folder of the virtualenv's console scripts (pph_recorder, ...)."""


LONG_FIRST = ('test_moving_tones_graph.py', 'test_experiment.py', 'test_twin_graph.py',
              'test_sensitivity_core_loop.py', 'test_params_file.py', 'test_fxlms.py',
              'test_colcon_layout.py', 'test_never_worse_core_loop.py',
              'test_harmonic_rise.py')
"""Files of the longest tests (30-240 s each), collected first so that pytest-xdist's
workers do not end on them one after the other (order only: none depends on another)."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test that uses a ROS fixture ``ros``; the longest files first."""
    for item in items:
        if ROS_FIXTURES.intersection(getattr(item, 'fixturenames', ())):
            item.add_marker(pytest.mark.ros)
    rank = {name: k for k, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FIRST)))    # stable


def _worker() -> tuple[int, int]:
    """(this pytest-xdist worker's number, the number of workers); (0, 1) without xdist."""
    name = os.environ.get('PYTEST_XDIST_WORKER', 'gw0')
    return int(name.removeprefix('gw') or 0), int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', 1))


def next_domain_id() -> int:
    """A ROS domain id not used before in this test session, in [DOMAIN_MIN, DOMAIN_LIMIT).

    With pytest-xdist, worker k of W takes the ids congruent to k modulo W, so that
    parallel workers never share a domain.
    """
    worker, workers = _worker()
    span = (DOMAIN_LIMIT - DOMAIN_MIN) // workers * workers
    return DOMAIN_MIN + (_domain_base - DOMAIN_MIN + workers * next(_domain_counter)
                         + worker) % span


# UDP only, for the test process and every node it starts: the tests SIGKILL nodes on
# purpose, which leaves Fast DDS shared-memory port files locked in /dev/shm, and a later
# participant can then pick a dead shared-memory channel and silently receive nothing
# (seen: a controller that never got /pph/accel). Loopback UDP has no such state.
os.environ.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')


@pytest.fixture
def ros_env() -> dict[str, str]:
    """Environment for ROS processes of one test: own domain, localhost discovery only."""
    env = dict(os.environ)
    env.pop('ROS_LOCALHOST_ONLY', None)  # deprecated; conflicts with the discovery range
    env.update(
        ROS_DOMAIN_ID=str(next_domain_id()),
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
        RMW_IMPLEMENTATION='rmw_fastrtps_cpp',
        PYTHONUNBUFFERED='1',
    )
    return env


class NodeProcess:
    """A console script of the package run as a separate process, output kept in files.

    Started with ``hexapod_vibration.tools.processes.spawn``: own session (signals from the
    terminal go to pytest only) and a parent-death signal (it dies with pytest, even when
    pytest is killed).
    """

    def __init__(self, executable: str, args: list[str], env: dict[str, str], log_dir: Path,
                 cwd: Path | None = None, command: list[str] | None = None):
        """Start ``BIN_DIR/executable args`` (or ``command``) with ``env``, logs in ``log_dir``."""
        self.name = executable
        self.stdout_path = log_dir / f'{executable}.{id(self)}.stdout'
        self.stderr_path = log_dir / f'{executable}.{id(self)}.stderr'
        self.child = processes.spawn(executable, command or [str(BIN_DIR / executable), *args],
                                     log=self.stdout_path, stderr_log=self.stderr_path,
                                     env=env, cwd=cwd)
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
        out = self.stdout_path.read_text(errors='replace')
        err = self.stderr_path.read_text(errors='replace')
        return f'--- {self.name} stdout ---\n{out}--- {self.name} stderr ---\n{err}'


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
        """Stop every process still running (SIGINT, then SIGKILL)."""
        for process in self.started:
            process.stop(timeout_s=10.0)


@pytest.fixture
def node_processes(ros_env: dict[str, str], tmp_path: Path) -> Iterator[NodeProcesses]:
    """Factory of :class:`NodeProcess` on the test's domain; none survives the test."""
    processes = NodeProcesses(ros_env, tmp_path)
    try:
        yield processes
    finally:
        processes.stop_all()


class RosTestContext:
    """An rclpy context of the test process on the test's domain, with an executor."""

    def __init__(self, domain_id: int):
        """Initialise rclpy on ``domain_id`` without touching the process's signal handlers."""
        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(
            context=self.context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Node] = []

    def create_node(self, name: str, **kwargs) -> Node:
        """A node in this context, spun by :meth:`wait_for`."""
        node = rclpy.create_node(name, context=self.context, **kwargs)
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def wait_for(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        step: Callable[[], None] | None = None,
        spin: Callable[[], None] | None = None,
    ) -> bool:
        """Spin until ``predicate()`` holds; False after ``timeout_s`` (a hang guard only).

        Args:
            predicate: Condition to wait for.
            timeout_s: Give up after this long (s); choose it generously.
            step: Called before each spin (e.g. to publish something repeatedly).
            spin: One spin (default: the context's executor, up to 50 ms).
        """
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                return False
            if step is not None:
                step()
            if spin is None:
                self.executor.spin_once(timeout_sec=0.05)
            else:
                spin()
        return True

    def shutdown(self) -> None:
        """Destroy the nodes and shut the context down."""
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def ros_context(
    ros_env: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> Iterator[RosTestContext]:
    """An in-test rclpy context on the same domain as the test's node processes."""
    for key in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'RMW_IMPLEMENTATION'):
        monkeypatch.setenv(key, ros_env[key])
    monkeypatch.delenv('ROS_LOCALHOST_ONLY', raising=False)
    context = RosTestContext(int(ros_env['ROS_DOMAIN_ID']))
    try:
        yield context
    finally:
        context.shutdown()
