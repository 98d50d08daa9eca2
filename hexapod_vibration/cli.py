"""What every executable of the package shares: ``--help``, argument errors, signals, exit.

Standard library only, so that it costs nothing before the heavy imports (rclpy, numpy,
scipy, matplotlib) it lets an executable defer until its arguments are known to be good.

- **Arguments.** :class:`ArgumentParser` reports a bad argument in one line naming it and
  exits 2; the argument types below (:func:`number`, :func:`output_dir`, ...) check values
  before any work starts. Node executables take ROS arguments only
  (:func:`node_command_line`): ``--help`` prints the node's parameters from
  ``parameter_specs`` and exits 0; anything else before ``--ros-args`` is an error, and so is
  a ``--params-file`` that does not exist or is not a YAML mapping.
- **Signals.** :func:`install_stop_handlers` makes the first SIGINT or SIGTERM raise
  :class:`StopSignal` (a ``KeyboardInterrupt``) in the main thread, wherever it is,
  including in the middle of the start-up imports (a raise swallowed there, e.g. in an
  import lock's callback, is caught up by :func:`exit_if_stopped` after the imports). The
  exit code is ``128 + the first signal``: 130 for SIGINT, 143 for SIGTERM. Clean-up runs
  inside :func:`deferred`, which holds a later signal back until the section ends, so a
  clean shutdown (stopping child processes, closing a bag, moving finished outputs into
  place) is never cut short. An object the signal cut short in its ``__init__`` prints
  nothing when it is collected (:func:`quiet_finalizers_after_stop`).
- **Exit.** :func:`exit_now` flushes and ends the process with ``os._exit``, after the
  caller's clean shutdown: the interpreter's own teardown (module cleanup and a final
  garbage collection of every object rclpy, numpy and scipy allocated) cost a node about
  0.2-0.45 s of CPU on the project machine and does nothing a finished node needs.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignal(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived: unwind, shut down cleanly, exit ``128 + signum``."""

    def __init__(self, signum: int) -> None:
        """Remember which signal it was."""
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        """The shell's convention: 128 + the signal number (130 SIGINT, 143 SIGTERM)."""
        return 128 + self.signum


class _StopState:
    """The signal state of this process (one per process: signals are per process)."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.raised = False
        self.deferring = 0

    def handler(self, signum: int, frame: object) -> None:
        if self.signum is None:
            self.signum = signum
        if self.deferring:
            return
        # Raised again by a later signal: the first one may have been swallowed (raised
        # inside an import lock's or a finalizer's callback, which Python only prints).
        self.raised = True
        raise StopSignal(self.signum)


_STATE = _StopState()


def install_stop_handlers() -> None:
    """SIGINT and SIGTERM raise :class:`StopSignal` once (idempotent; main thread only).

    Also installs :func:`quiet_finalizers_after_stop` as ``sys.unraisablehook``.
    """
    for signum in STOP_SIGNALS:
        signal.signal(signum, _STATE.handler)
    sys.unraisablehook = quiet_finalizers_after_stop


def quiet_finalizers_after_stop(unraisable: object) -> None:
    """``sys.unraisablehook``: after a stop signal, a finalizer's AttributeError is not printed.

    The signal is raised wherever the main thread is, so it can cut an object's
    ``__init__`` short; the half-built object's ``__del__`` then fails on an attribute it
    never got and Python prints "Exception ignored in ... Traceback" (rclpy's executor
    ``Task``, made for every callback it runs: ``'Task' object has no attribute
    '_exception'`` at a Ctrl-C, seen once in CI). Every other unraisable error, and any
    before a stop, goes to Python's own hook.
    """
    if _STATE.signum is not None and isinstance(getattr(unraisable, "exc_value", None),
                                                AttributeError):
        return
    sys.__unraisablehook__(unraisable)


def stop_requested() -> int | None:
    """The first stop signal received (``signal.SIGINT`` ...), or None."""
    return _STATE.signum


def exit_if_stopped() -> None:
    """Raise :class:`StopSignal` if a stop signal came and its exception was lost."""
    if _STATE.signum is not None and not _STATE.deferring:
        _STATE.raised = True
        raise StopSignal(_STATE.signum)


def interrupted_exit_code(exc: BaseException | None = None) -> int:
    """Exit code after an interruption: ``128 + signal`` (130 when it was a plain Ctrl-C)."""
    if isinstance(exc, StopSignal):
        return exc.exit_code
    return 128 + (_STATE.signum or signal.SIGINT)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold a stop signal's exception back until the section ends, then raise it."""
    _STATE.deferring += 1
    try:
        yield
    finally:
        _STATE.deferring -= 1
    if not _STATE.deferring and _STATE.signum is not None and not _STATE.raised:
        _STATE.raised = True
        raise StopSignal(_STATE.signum)


def exit_now(code: int) -> None:
    """Flush stdout and stderr, then end the process at once with ``code`` (no teardown)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


# ------------------------------------------------------------------------ arguments
class ArgumentParser(argparse.ArgumentParser):
    """``argparse`` with one-line errors: ``prog: error: argument --x: reason``, exit 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        """Print the one-line error and exit 2 (argparse prints the whole usage first)."""
        self.exit(EXIT_USAGE, f"{self.prog}: error: {' '.join(message.split())}\n")


def fail(prog: str, message: str) -> int:
    """Report a bad input in one line on stderr; returns :data:`EXIT_USAGE`."""
    print(f"{prog}: error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)
    return EXIT_USAGE


def number(low: float | None = None, high: float | None = None, unit: str = "",
           low_open: bool = False, high_open: bool = False,
           integer: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number within the given bounds (open or closed)."""
    left = "(" if low_open else "["
    right = ")" if high_open else "]"
    span = f"{left}{'-inf' if low is None else f'{low:g}'}, " \
           f"{'inf' if high is None else f'{high:g}'}{right}"
    what = f"{'an integer' if integer else 'a number'} in {span}{' ' + unit if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
        inside = math.isfinite(value) and \
            (low is None or value > low or (not low_open and value == low)) and \
            (high is None or value < high or (not high_open and value == high))
        if not inside:
            raise argparse.ArgumentTypeError(f"must be {what}, got {text}")
        return value

    parse.__name__ = "number"
    return parse


MAX_RUN_S = 86400.0
"""Longest run an argument may ask for (s): one day of simulated or wall time."""
duration_s = number(0.0, MAX_RUN_S, "s", low_open=True)
"""An argparse type: a duration in (0, 1 day] s."""


def output_dir(text: str) -> Path:
    """An argparse type: a directory to write into (created later); never an existing file."""
    path = Path(text).expanduser()
    for part in (path, *path.parents):
        if part.exists():
            if not part.is_dir():
                raise argparse.ArgumentTypeError(f"{part} exists and is not a directory")
            if not os.access(part, os.W_OK | os.X_OK):
                raise argparse.ArgumentTypeError(f"{part} is not writable")
            break
    return path


def existing_dir(text: str) -> Path:
    """An argparse type: a directory that exists."""
    path = Path(text).expanduser()
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} is not a directory" if path.exists()
                                         else f"{path} does not exist")
    return path


def existing_file(text: str) -> Path:
    """An argparse type: a readable file."""
    path = Path(text).expanduser()
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{path} is not a file" if path.exists()
                                         else f"{path} does not exist")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{path} is not readable")
    return path


# ------------------------------------------------------------------------ node executables
ROS_ARGS = "--ros-args"


def node_usage(executable: str, nodes: Sequence[str]) -> str:
    """``--help`` of a node executable: usage, and every parameter from its spec."""
    from hexapod_vibration.parameter_specs import NODE_SPECS

    specs = [NODE_SPECS[n] for n in nodes]
    summary = "; ".join(f"{s.node}: {s.summary}" for s in specs) if len(specs) > 1 \
        else specs[0].summary
    lines = [f"usage: {executable} [-h] [--ros-args [-p NAME:=VALUE ...] "
             "[--params-file FILE] ...]",
             f"       ros2 run hexapod_vibration {executable} --ros-args ...", "",
             f"{executable}: {summary}.", "",
             "Parameters (-p NAME:=VALUE, or a params file; (ro) = read-only):"]
    for spec in specs:
        if len(specs) > 1:
            lines.append(f"  {spec.node} (-p {spec.node}:NAME:=VALUE):")
        for p in spec.parameters:
            kind = p.type + (f", {p.unit}" if p.unit else "")
            detail = p.range_text()
            lines.append(f"    {p.name}{' (ro)' if p.read_only else ''}: {kind}, default "
                         f"{p.default!r}{'; ' + detail if detail else ''}")
    lines += ["", "SIGINT exits 130, SIGTERM 143, after a clean shutdown; a bad argument or "
              "parameter exits 2 with the reason."]
    return "\n".join(lines)


def node_command_line(executable: str, nodes: Sequence[str],
                      argv: Sequence[str] | None = None) -> list[str]:
    """Check a node executable's command line; returns the arguments for ``rclpy.init``.

    ``-h``/``--help`` before ``--ros-args`` print :func:`node_usage` and exit 0; any other
    argument there, or a ``--params-file`` that is missing or not a YAML mapping, exits 2
    with a one-line reason. Runs before rclpy is imported.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    own = args[:args.index(ROS_ARGS)] if ROS_ARGS in args else args
    if any(a in ("-h", "--help") for a in own):
        with contextlib.suppress(BrokenPipeError):      # e.g. piped into head
            print(node_usage(executable, nodes), flush=True)
        exit_now(EXIT_OK)
    if own:
        exit_now(fail(executable, f"unrecognized arguments: {' '.join(own)} (a node takes "
                                  f"ROS arguments only: {executable} --ros-args -p NAME:=VALUE)"))
    reason = _params_file_problem(args)
    if reason:
        exit_now(fail(executable, reason))
    return args


def _params_file_problem(args: Sequence[str]) -> str:
    """Why a ``--params-file`` argument cannot be used, or ``''``."""
    for i, arg in enumerate(args):
        if arg != "--params-file":
            continue
        if i + 1 >= len(args):
            return "argument --params-file: expected a file"
        path = Path(args[i + 1])
        if not path.is_file():
            return (f"argument --params-file: {path} "
                    f"{'is not a file' if path.exists() else 'does not exist'}")
        try:
            import yaml

            content = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            return f"argument --params-file: cannot read {path}: {' '.join(str(exc).split())}"
        if not isinstance(content, dict):
            return (f"argument --params-file: {path} is not a ROS params file (a mapping "
                    "node: {ros__parameters: {...}})")
    return ""
