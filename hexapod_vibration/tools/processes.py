"""Child processes that never outlive their parent: one module for the runner, tests, bench.

Every child is started (:func:`spawn`) in its own session and process group (a Ctrl-C
in the terminal reaches the parent only, which then stops its children in order) with a
parent-death signal: ``prctl(PR_SET_PDEATHSIG, SIGTERM)`` in the child before it execs,
so that when the parent dies, even by SIGKILL, the kernel sends the child SIGTERM and it
shuts down cleanly (a recorder closes its bag). The race where the parent dies between
the fork and the ``prctl`` is closed by checking the parent's pid right after.

:meth:`Child.stop` asks politely (SIGINT, or SIGTERM), waits, then kills the whole group.

Linux only (``prctl``); elsewhere the children are still in their own group and stopped
by :func:`stop_all`, but a SIGKILL of the parent would leave them running.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

PR_SET_PDEATHSIG = 1
PARENT_DEATH_SIGNAL = signal.SIGTERM
STOP_TIMEOUT_S = 15.0
"""How long :meth:`Child.stop` waits for a clean exit (s) before SIGKILL of the group."""

try:
    _prctl = ctypes.CDLL(None, use_errno=True).prctl     # resolved here, not in the child
except (OSError, AttributeError):   # not Linux
    _prctl = None


def die_with_parent(parent_pid: int) -> None:
    """In a child (a ``preexec_fn``, or after a fork): SIGTERM when ``parent_pid`` dies."""
    if _prctl is not None:
        _prctl(PR_SET_PDEATHSIG, int(PARENT_DEATH_SIGNAL), 0, 0, 0)
    if os.getppid() != parent_pid:     # the parent died before the prctl: go now
        os.kill(os.getpid(), PARENT_DEATH_SIGNAL)


@dataclass
class Child:
    """One child process, its log, and how to stop it."""

    name: str
    process: subprocess.Popen
    log: Path | None = None
    stderr_log: Path | None = None
    _files: list = field(default_factory=list, repr=False)

    @property
    def pid(self) -> int:
        """Process id (also its process group id)."""
        return self.process.pid

    def alive(self) -> bool:
        """True while the process runs."""
        return self.process.poll() is None

    def wait(self, timeout_s: float | None = None) -> int | None:
        """Exit code, or None if still running after ``timeout_s``."""
        try:
            return self.process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def send(self, signum: int) -> None:
        """Send ``signum`` to the process (not its group) if it still runs."""
        if self.alive():
            with contextlib.suppress(ProcessLookupError):
                self.process.send_signal(signum)

    def stop(self, timeout_s: float = STOP_TIMEOUT_S, signum: int = signal.SIGINT) -> int:
        """``signum``, wait up to ``timeout_s``, then SIGKILL the group; the exit code."""
        if self.alive():
            self.send(signum)
            if self.wait(timeout_s) is None:
                self.kill()
        self.close_logs()
        return self.process.returncode

    def kill(self) -> None:
        """SIGKILL the process group (the process and anything it started) and reap."""
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait()

    def close_logs(self) -> None:
        """Close the parent's handles of the log files."""
        for stream in self._files:
            stream.close()
        self._files.clear()

    def tail(self, lines: int = 15) -> str:
        """Last lines of its log (stdout, then stderr if separate)."""
        text = ""
        for path in (self.log, self.stderr_log):
            if path is not None and path.exists():
                text += path.read_text(errors="replace")
        return "\n".join(text.splitlines()[-lines:])


def spawn(name: str, command: Sequence[str], log: Path | None = None,
          stderr_log: Path | None = None, env: dict[str, str] | None = None,
          cwd: Path | None = None) -> Child:
    """Start ``command`` in its own session, dying with this process (see module docstring).

    Output goes to ``log`` (stdout, and stderr too unless ``stderr_log``), else is discarded.
    """
    files = []
    stdout = stderr = subprocess.DEVNULL
    if log is not None:
        stdout = stderr = open(log, "wb")  # noqa: SIM115 (closed by Child.close_logs)
        files.append(stdout)
    if stderr_log is not None:
        stderr = open(stderr_log, "wb")  # noqa: SIM115
        files.append(stderr)
    elif log is not None:
        stderr = subprocess.STDOUT
    parent = os.getpid()
    process = subprocess.Popen(
        list(command), stdin=subprocess.DEVNULL, stdout=stdout, stderr=stderr,
        env=env, cwd=cwd, start_new_session=True,
        preexec_fn=lambda: die_with_parent(parent))  # noqa: PLW1509 (only a prctl)
    return Child(name, process, log, stderr_log, files)


def spawn_module(name: str, module: str, args: Sequence[str], log_dir: Path,
                 env: dict[str, str] | None = None) -> Child:
    """``python -m module args`` with unbuffered output into ``log_dir/name.log``."""
    env = dict(os.environ if env is None else env, PYTHONUNBUFFERED="1")
    return spawn(name, [sys.executable, "-m", module, *args], log=log_dir / f"{name}.log",
                 env=env)


def stop_all(children: Iterable[Child], timeout_s: float = STOP_TIMEOUT_S,
             signum: int = signal.SIGINT) -> list[int]:
    """Stop each child in turn (the given order); their exit codes."""
    return [child.stop(timeout_s, signum) for child in children]
