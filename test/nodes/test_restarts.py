"""Any single node killed (SIGKILL) and started again: the loop resumes by itself.

A restarted driver starts again at sample 0; controllers that dropped every index not above
the last one seen deadlocked lockstep in the handshake and left realtime with no command.
With the run identity (``layout.dim[2]``) a controller adopts the new run within a few
messages (core/loop/sample_sequence.py). Judged on the data, per run and sample index: the
restarted loop is answered from a sample within the first second of simulated progress (1000
samples). In lockstep the driver then waits for every sample again: by its own counts, 1000
samples without a timeout or a miss (after a restarted controller, once the driver has
matched its new publisher; a controller a loaded machine stalls for five 0.5 s waits is
dropped by the watchdog until it answers again, so the window is the first clean one, and
the hang guard fails a loop never waited for again), and every answer this listener saw of
them was applied. Realtime keeps up with the wall clock only on an idle machine, so there
the test asks that answers come back, not that every sample is answered.
"""

from __future__ import annotations

import numpy as np
import pytest
from node_graph import Diagnostics, StrutTopic, wait_until

from hexapod_vibration.contract import DRIVER_STATUS
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import saturate_commands
from hexapod_vibration.paths import config_path

STRUT = load_model_config(config_path("pph_model.yaml")).strut
RESUME_WITHIN_SAMPLES = 1000      # 1 s of simulated progress
CHECKED_SAMPLES = 1000
REALTIME_MIN_ANSWERS = 100        # answers of the new run or process come back (load-tolerant)
BEFORE_SAMPLES = 500
CATCH_UP_SAMPLES = 20
"""A restarted controller first answers what its queue (10 deep) holds, samples the
driver (not waiting for it then) may have passed; then lockstep waits for it again."""


CONTROLLERS = {
    # stream: (executable, command topic, its arguments); the raw notch (P = I) adapts from
    # the first sample, so its commands are not zero.
    "pointing": ("pointing_controller", "/pph/pointing_command", []),
    "notch": ("notch_controller", "/pph/notch_command",
              ["-p", "adaptation:=raw", "-p", "mu:=1e-5", "-p", "tone_frequencies_hz:=[40.0]",
               "-p", "auto_identify:=false"]),
}


CASES = [("lockstep", "pointing"), ("lockstep", "notch"), ("realtime", "notch")]
"""(clock mode, restarted stream): both controllers share the loop port that adopts a new
run (``ros/messages.ControllerLoopPort``); realtime with the pointing controller too was
dropped for the suite's time (10-19 s a case)."""

SETTLE_SAMPLES = 100
MIN_CHECKED_FORCES = 100


def _driver_args(mode: str, stream: str) -> list[str]:
    return ["--ros-args", "-p", f"clock_mode:={mode}", "-p", f"lockstep_controllers:=[{stream}]",
            "-p", "lockstep_timeout_s:=0.5"]


def _controller(node_processes, stream: str, *extra: str):
    executable, _, args = CONTROLLERS[stream]
    return node_processes.start(executable, "--ros-args", *args, *extra)


def _applied(stream: str, command: np.ndarray) -> np.ndarray:
    """The force the driver applies for this controller's command alone."""
    notch, pointing = (command, np.zeros(6)) if stream == "notch" else (np.zeros(6), command)
    return saturate_commands(notch, pointing, STRUT)


def _runs(topic: StrutTopic) -> list:
    return [run for run in topic.by_run if run is not None]


def _driver_reports(diagnostics: Diagnostics, run: int) -> dict[int, tuple[int, int]]:
    """The driver's lockstep (``timeouts``, ``missed_samples``) by reported sample of ``run``.

    The driver reports every 1000 samples. Equal counts at two reports = every sample
    between them was answered by every waited controller before the driver advanced, by
    the driver's own account, whatever this listener received.
    """
    return {int(v["sample"]): (int(v["timeouts"]), int(v["missed_samples"]))
            for v in diagnostics.history_values(DRIVER_STATUS)
            if v.get("run") == str(run) and "timeouts" in v and "sample" in v}


def _driver_counts_over(diagnostics: Diagnostics, run: int, first: int
                        ) -> list[tuple[int, int]] | None:
    """The counts at the first report at or after ``first`` and CHECKED_SAMPLES later."""
    reports = _driver_reports(diagnostics, run)
    start = min((n for n in reports if n >= first), default=None)
    if start is None or start + CHECKED_SAMPLES not in reports:
        return None
    return [reports[start], reports[start + CHECKED_SAMPLES]]


def _waited_again_from(diagnostics: Diagnostics, run: int, first: int) -> int | None:
    """The first report at or after ``first`` that opens CHECKED_SAMPLES without a miss.

    A restarted controller is waited for again once the driver has matched its new
    publisher and accepted a command from it; until then the driver runs on without it
    (counted as missed), thousands of samples in a fraction of a second of wall time, so
    where this starts depends on discovery, not on the product's rule.
    """
    reports = _driver_reports(diagnostics, run)
    return min((n for n in reports if n >= first and n + CHECKED_SAMPLES in reports
                and reports[n] == reports[n + CHECKED_SAMPLES]), default=None)


def _pairs_seen(commands: dict[int, np.ndarray], force: dict[int, np.ndarray],
                first: int) -> list[int]:
    """Samples from ``first + SETTLE_SAMPLES`` whose command and force this listener saw."""
    return [n for n in sorted(force) if n in commands and n >= first + SETTLE_SAMPLES]


def _answers_from(commands: dict[int, np.ndarray], first: int) -> int:
    return sum(1 for n in commands if n >= first)


def _check_resumed(mode: str, stream: str, commands: dict[int, np.ndarray],
                   force: dict[int, np.ndarray], first: int,
                   counts: list[tuple[int, int]] | None = None) -> None:
    if mode == "realtime":
        # answers come back (the callers waited for them): at load 8 a controller can
        # answer none of one second of samples and catch up later
        assert _answers_from(commands, first) >= REALTIME_MIN_ANSWERS, first
        return
    # Every sample answered, by the driver's account: neither its timeout nor its missed
    # sample count moves over the window. What this listener received is no measure of
    # that: a slow reader on a loaded machine loses messages the driver got (CI: 971 of
    # the 1000 checked, with the driver's counts unchanged).
    assert counts is not None and counts[0] == counts[1], (first, counts)
    window = range(first, first + CHECKED_SAMPLES)
    print(f"listener saw {sum(n in commands for n in window)} of the {CHECKED_SAMPLES} "
          f"commands of the window; driver (timeouts, missed) {counts}")
    # Lockstep pairs them: the driver applied each one at its sample. (A restarted driver's
    # first forces may be published before it has discovered this listener, on a loaded
    # machine for longer than the window: every force seen of the new run is checked,
    # after the first SETTLE_SAMPLES, where a controller still taking up the new run may
    # answer after the 0.5 s lockstep wait and the driver applies the safe zero instead.)
    seen = _pairs_seen(commands, force, first)
    assert len(seen) >= MIN_CHECKED_FORCES, len(seen)
    for n in seen:
        np.testing.assert_allclose(force[n], _applied(stream, commands[n]),
                                   rtol=0, atol=1e-12, err_msg=str(n))


@pytest.mark.parametrize("mode, stream", CASES)
def test_restarted_driver_is_answered_within_a_second(ros_context, node_processes, mode,
                                                      stream):
    driver = node_processes.start("pph_driver", *_driver_args(mode, stream))
    pointing = _controller(node_processes, stream)
    node = ros_context.create_node("restart_listener")
    commands = StrutTopic(node, CONTROLLERS[stream][1])
    force = StrutTopic(node, "/pph/actuator_force")
    diagnostics = Diagnostics(node)

    def logs() -> str:
        return "\n".join(p.output() for p in node_processes.started)

    assert wait_until(ros_context, lambda: _runs(commands)
                      and len(commands.by_run[_runs(commands)[0]]) > BEFORE_SAMPLES), logs()
    old_run = _runs(commands)[0]
    driver.process.kill()                  # SIGKILL, at any sample
    assert driver.wait(60.0) is not None
    again = node_processes.start("pph_driver", *_driver_args(mode, stream))

    def new_run():
        return next((r for r in _runs(commands) if r != old_run), None)

    def checked_forces_seen() -> bool:
        # The listener may discover the restarted driver's force topic late on a loaded
        # machine (samples published before that are never seen): wait for the forces
        # _check_resumed judges, not for one force index past the window.
        run = new_run()
        if run is None or run not in force.by_run or run not in commands.by_run:
            return False
        first = min(commands.by_run[run])
        if mode == "realtime":
            return _answers_from(commands.by_run[run], first) >= REALTIME_MIN_ANSWERS
        waited = _waited_again_from(diagnostics, run, first + SETTLE_SAMPLES)
        return waited is not None and len(_pairs_seen(
            commands.by_run[run], force.by_run[run], waited)) >= MIN_CHECKED_FORCES

    resumed = wait_until(ros_context, lambda: not pointing.running() or checked_forces_seen())
    assert resumed and pointing.running() and again.running(), (
        new_run(), new_run() is not None and sorted(_driver_reports(
            diagnostics, new_run()).items())[-12:], logs())
    run = new_run()
    first = min(commands.by_run[run])
    print(f"{mode}: new run answered from sample {first}")
    assert first <= RESUME_WITHIN_SAMPLES, first
    if mode == "lockstep":
        # a controller the loaded machine stalls for five 0.5 s waits is dropped by the
        # watchdog and the loop runs on without it until it answers again (counted):
        # judged from the first 1000 samples the driver's counts show clean
        first = _waited_again_from(diagnostics, run, first + SETTLE_SAMPLES)
        print(f"{mode}: every sample answered from sample {first}")
    _check_resumed(mode, stream, commands.by_run[run], force.by_run[run], first,
                   _driver_counts_over(diagnostics, run, first))
    for process in (again, pointing):
        assert process.stop() == 130, process.output()     # SIGINT: 128 + 2


@pytest.mark.parametrize("mode, stream", CASES)
def test_restarted_controller_is_waited_for_again(ros_context, node_processes, mode, stream):
    driver = node_processes.start("pph_driver", *_driver_args(mode, stream))
    pointing = _controller(node_processes, stream)
    node = ros_context.create_node("restart_listener")
    commands = StrutTopic(node, CONTROLLERS[stream][1])
    force = StrutTopic(node, "/pph/actuator_force")
    diagnostics = Diagnostics(node)

    def logs() -> str:
        return "\n".join(p.output() for p in node_processes.started)

    def current_run() -> int | None:
        value = diagnostics.value(DRIVER_STATUS, "run")
        return int(value) if value else None

    # the driver's run as its /diagnostics names it, and that run's commands (the full
    # suite once saw the status name a run none of the commands received so far carried)
    assert wait_until(ros_context, lambda: (r := current_run()) is not None
                      and len(commands.by_run.get(r, {})) > BEFORE_SAMPLES), (
        current_run(), sorted(commands.by_run, key=str), logs())
    run = current_run()
    before = commands.last_index
    assert all(np.any(c) for n, c in commands.by_run[run].items() if n >= 100)   # working
    pointing.process.kill()
    assert pointing.wait(60.0) is not None
    # Switched off, the new process answers exactly zero: its answers are told apart from
    # the old one's that this process may still receive (it can lag the loop).
    again = _controller(node_processes, stream, "-p", "enabled:=false")

    def first_new() -> int | None:
        return next((n for n, c in sorted(commands.by_run.get(run, {}).items())
                     if n > before and not np.any(c)), None)

    def waited_from() -> int | None:
        """Lockstep: where the driver waits for the new process again (its own account)."""
        if first_new() is None:
            return None
        return _waited_again_from(diagnostics, run, first_new() + CATCH_UP_SAMPLES)

    def checked() -> bool:
        if first_new() is None:
            return False
        if mode == "realtime":
            return _answers_from(commands.by_run[run],
                                 first_new() + CATCH_UP_SAMPLES) >= REALTIME_MIN_ANSWERS
        first = waited_from()
        return first is not None and len(_pairs_seen(
            commands.by_run[run], force.by_run.get(run, {}), first)) >= MIN_CHECKED_FORCES

    resumed = wait_until(ros_context, lambda: not driver.running() or checked())
    if not (resumed and driver.running() and again.running()):
        print(logs())       # whole, in the report's captured output (the message is cut)
    assert resumed and driver.running() and again.running(), (
        first_new(), commands.last_index, force.last_index,
        sorted(_driver_reports(diagnostics, run).items())[-12:],
        diagnostics.values(DRIVER_STATUS), logs())
    old_last = max(n for n, c in commands.by_run[run].items() if np.any(c))
    print(f"{mode}: last answer of the killed process {old_last}, answered again from "
          f"{first_new()}")
    assert first_new() > old_last
    first = first_new() + CATCH_UP_SAMPLES if mode == "realtime" else waited_from()
    print(f"{mode}: waited for again from sample {first}")
    _check_resumed(mode, stream, commands.by_run[run], force.by_run[run], first,
                   _driver_counts_over(diagnostics, run, first))
    for process in (driver, again):
        assert process.stop() == 130, process.output()     # SIGINT: 128 + 2
