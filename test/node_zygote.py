"""The package's console scripts started as forks of one warm process (the tests' node starts).

Every node process a test starts imports rclpy, numpy and scipy.signal first: ~2 s of CPU,
more than many of those tests' own work, on a 2-core machine where the suite is CPU-bound.
This process imports them once; each start is then a ``fork`` that sets the test's
environment, working directory, arguments and output files and calls the console script's
entry point, as the script would (``tests run real nodes in real processes``: each node is
its own process, with its own rclpy context and DDS participant; nothing is initialised
here before the fork, no thread runs here).

Protocol with the one client (the pytest worker that started it), JSON lines on stdin and
stdout:

- in: ``{"script": NAME, "argv": [...], "env": {...}, "cwd": PATH|null, "stdout": PATH,
  "stderr": PATH}``; out: ``{"pid": PID}`` or ``{"error": TEXT}``;
- out, whenever a started process ends: ``{"exit": PID, "code": CODE}`` (CODE as
  ``subprocess.Popen.returncode``: negative for a signal).

A started process runs in its own session and dies with this one (``PR_SET_PDEATHSIG``,
``tools.processes.die_with_parent``), which dies with the pytest process that started it.
"""

from __future__ import annotations

import importlib
import json
import os
import select
import signal
import sys
from importlib.metadata import entry_points

from hexapod_vibration.core.model.kernel_choice import (
    compiled_continuation_kernels,
    compiled_kernels,
    compiled_law_kernels,
)
from hexapod_vibration.tools.processes import die_with_parent

PRELOADED = (
    "rclpy", "rclpy.node", "numpy", "scipy.signal", "scipy.interpolate",
    "hexapod_vibration.nodes.pph_driver", "hexapod_vibration.nodes.notch_controller",
    "hexapod_vibration.nodes.pointing_controller", "hexapod_vibration.nodes.recorder",
    "hexapod_vibration.nodes.pph_graph",
)
"""What every node start would import (the zygote pays it once)."""


def _scripts() -> dict[str, str]:
    """Console script name -> ``module:function`` of the installed package."""
    return {ep.name: ep.value for ep in entry_points(group="console_scripts")
            if ep.value.startswith("hexapod_vibration.")}


def _send(message: dict) -> None:
    os.write(1, (json.dumps(message) + "\n").encode())


def _child(request: dict, target: str, zygote_pid: int) -> None:
    """In the fork: become the script's process, run its entry point, never return."""
    code = 1
    try:
        os.setsid()
        signal.set_wakeup_fd(-1)
        for signum in (signal.SIGCHLD, signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_DFL)
        die_with_parent(zygote_pid)
        devnull = os.open(os.devnull, os.O_RDONLY)
        out = os.open(request["stdout"], os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        err = os.open(request["stderr"], os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        for fd, to in ((devnull, 0), (out, 1), (err, 2)):
            os.dup2(fd, to)
            os.close(fd)
        os.closerange(3, 256)
        if request.get("cwd"):
            os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        sys.argv = list(request["argv"])
        module, _, function = target.partition(":")
        getattr(importlib.import_module(module), function)()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:  # noqa: BLE001 - as the interpreter would: traceback, exit 1
        import traceback
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def _start(request: dict, scripts: dict[str, str]) -> dict:
    target = scripts.get(request.get("script", ""))
    if target is None:
        return {"error": f"not a console script of the package: {request.get('script')!r}"}
    sys.stdout.flush()
    sys.stderr.flush()
    zygote = os.getpid()
    pid = os.fork()
    if pid == 0:
        _child(request, target, zygote)
    return {"pid": pid}


def _reap() -> None:
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        _send({"exit": pid, "code": os.waitstatus_to_exitcode(status)})


def main() -> None:
    """Import, say ready, serve start requests until stdin closes."""
    for module in PRELOADED:
        importlib.import_module(module)
    compiled_kernels()          # numba and the plant's kernels, where installed (~0.4 s)
    compiled_law_kernels()      # the pointing law's
    compiled_continuation_kernels()     # its forecast's
    scripts = _scripts()
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _send({"ready": os.getpid()})
    pending = b""
    while True:
        ready, _, _ = select.select([0, wake_r], [], [])
        if wake_r in ready:
            os.read(wake_r, 4096)
            _reap()
        if 0 in ready:
            data = os.read(0, 65536)
            if not data:
                return
            pending += data
            while b"\n" in pending:
                line, pending = pending.split(b"\n", 1)
                _send(_start(json.loads(line), scripts))
        _reap()


if __name__ == "__main__":
    main()
