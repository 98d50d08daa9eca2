"""The client of ``test/node_zygote.py``: node processes forked from a warm process.

One zygote per pytest process (started on first use, dying with it). A started process is a
``tools.processes.Child`` around a :class:`ForkedPopen`, which offers what tests use of
``subprocess.Popen`` (``pid``, ``poll``, ``wait``, ``send_signal``, ``kill``,
``returncode``); its exit code comes from the zygote, its parent.

``HEXAPOD_TEST_FORK=0`` starts every node with its console script instead (``spawn``).
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from hexapod_vibration.tools import processes

ZYGOTE = Path(__file__).resolve().parent / "node_zygote.py"
ANSWER_TIMEOUT_S = 120.0
"""Longest wait for the zygote's imports or an answer (a hang guard)."""


def enabled() -> bool:
    """Whether node starts are forks of the zygote (default) or console scripts."""
    return os.environ.get("HEXAPOD_TEST_FORK", "1") != "0"


class Zygote:
    """The warm process and the exit codes it reported."""

    def __init__(self) -> None:
        """Start it and wait until it imported everything."""
        env = dict(os.environ, PYTHONUNBUFFERED="1", OPENBLAS_NUM_THREADS="1")
        parent = os.getpid()
        self.process = subprocess.Popen(
            [sys.executable, str(ZYGOTE)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            env=env, start_new_session=True,
            preexec_fn=lambda: processes.die_with_parent(parent))  # noqa: PLW1509
        self.exits: dict[int, int] = {}
        self._buffer = b""
        self._answer("ready")

    def start(self, request: dict) -> int:
        """Fork the console script of ``request`` (see ``node_zygote``); its pid."""
        self.process.stdin.write((json.dumps(request) + "\n").encode())
        self.process.stdin.flush()
        answer = self._answer("pid", "error")
        if "error" in answer:
            raise RuntimeError(answer["error"])
        return int(answer["pid"])

    def collect(self, timeout_s: float) -> None:
        """Record the exits reported, waiting up to ``timeout_s`` for the first line."""
        self._read(timeout_s)
        self._messages()

    def _answer(self, *keys: str) -> dict:
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while True:
            for message in self._messages():
                if any(key in message for key in keys):
                    return message
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self.process.poll() is not None:
                raise RuntimeError(f"node zygote: no {keys[0]} (exit {self.process.poll()})")
            self._read(remaining)

    def _messages(self) -> list[dict]:
        """Complete messages read so far: exits recorded, the others returned."""
        others = []
        while b"\n" in self._buffer:
            line, self._buffer = self._buffer.split(b"\n", 1)
            message = json.loads(line)
            if "exit" in message:
                self.exits[int(message["exit"])] = int(message["code"])
            else:
                others.append(message)
        return others

    def _read(self, timeout_s: float) -> None:
        fd = self.process.stdout.fileno()
        ready, _, _ = select.select([fd], [], [], max(timeout_s, 0.0))
        if ready:
            data = os.read(fd, 65536)
            if not data:
                raise RuntimeError(f"node zygote exited ({self.process.wait()})")
            self._buffer += data


_zygote: Zygote | None = None


def zygote() -> Zygote:
    """This pytest process's zygote (started on first use, again if it died)."""
    global _zygote
    if _zygote is None or _zygote.process.poll() is not None:
        _zygote = Zygote()
    return _zygote


class ForkedPopen:
    """The ``subprocess.Popen`` face of a process the zygote forked."""

    def __init__(self, script: str, argv: list[str], env: dict[str, str], cwd: Path | None,
                 stdout: Path, stderr: Path) -> None:
        """Start console script ``script`` with ``argv`` (its path first)."""
        for path in (stdout, stderr):          # there at once, as a spawned child's are
            path.touch()
        self.args = argv
        self._zygote = zygote()
        self.pid = self._zygote.start({
            "script": script, "argv": argv, "env": env, "stdout": str(stdout),
            "stderr": str(stderr), "cwd": None if cwd is None else str(cwd)})

    @property
    def returncode(self) -> int | None:
        """Exit code once the zygote reported it (negative: a signal), else None."""
        self._zygote.collect(0.0)
        return self._zygote.exits.get(self.pid)

    def poll(self) -> int | None:
        """As ``Popen.poll``."""
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """As ``Popen.wait``: the exit code; ``subprocess.TimeoutExpired`` after ``timeout``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while (code := self.returncode) is None:
            remaining = 1.0 if deadline is None else deadline - time.monotonic()
            if remaining <= 0:
                raise subprocess.TimeoutExpired(self.args, timeout)
            self._zygote.collect(min(remaining, 1.0))
        return code

    def send_signal(self, signum: int) -> None:
        """As ``Popen.send_signal``: nothing once it ended."""
        if self.returncode is None:
            os.kill(self.pid, signum)

    def kill(self) -> None:
        """As ``Popen.kill``: SIGKILL."""
        self.send_signal(signal.SIGKILL)


def start(name: str, argv: list[str], env: dict[str, str], cwd: Path | None,
          stdout: Path, stderr: Path) -> processes.Child:
    """Console script ``name`` forked by the zygote, as ``processes.spawn`` would return it."""
    popen = ForkedPopen(name, argv, env, cwd, stdout, stderr)
    return processes.Child(name, popen, stdout, stderr)  # type: ignore[arg-type]
