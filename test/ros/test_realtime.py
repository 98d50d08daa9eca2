"""realtime_priority and cpu_affinity: applied to every thread of a node, or refused."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hexapod_vibration.ros.realtime import (
    DEFAULT_REALTIME_PRIORITY,
    apply_scheduling,
    fifo_refusal,
)
from hexapod_vibration.tools.experiment import realtime_priority

HANG_GUARD_S = 60.0
BIN_DIR = Path(sys.executable).parent


def _threads(pid: int) -> list[int]:
    return [int(tid) for tid in os.listdir(f"/proc/{pid}/task")]


def _scheduled(process, text: str) -> bool:
    """The node logged that its scheduling was applied (or ended)."""
    return text in process.output() or not process.running()


def test_nothing_requested_changes_nothing():
    assert apply_scheduling(0, []) == ""


def test_priority_and_affinity_apply_to_every_thread(node_processes, ros_context):
    node = node_processes.start("pointing_controller", "--ros-args", "-p",
                                "realtime_priority:=10", "-p", "cpu_affinity:=[0]")
    assert ros_context.wait_for(lambda: _scheduled(node, "scheduling:"), HANG_GUARD_S)
    assert node.running(), node.output()
    assert "scheduling: CPUs [0], SCHED_FIFO priority 10" in node.output()
    threads = _threads(node.pid)
    assert len(threads) > 1                       # the DDS transport's threads too
    for tid in threads:
        assert os.sched_getscheduler(tid) == os.SCHED_FIFO, tid
        assert os.sched_getparam(tid).sched_priority == 10, tid
        assert os.sched_getaffinity(tid) == {0}, tid


def test_a_cpu_the_process_may_not_use_is_refused(node_processes):
    cpu = max(os.sched_getaffinity(0)) + 1
    node = node_processes.start("pointing_controller", "--ros-args", "-p",
                                f"cpu_affinity:=[{cpu}]")
    assert node.wait(HANG_GUARD_S) == 2, node.output()
    assert f"error: cpu_affinity [{cpu}]: this process may run on CPUs" in node.output()
    assert "Traceback" not in node.output()


@pytest.mark.skipif(not (shutil.which("setpriv") and shutil.which("prlimit")),
                    reason="needs util-linux setpriv and prlimit to withhold the permission")
def test_a_priority_the_os_does_not_permit_is_refused_in_one_line(node_processes):
    # No CAP_SYS_NICE and an rtprio limit of 0: what an unprivileged user has by default.
    command = ["prlimit", "--rtprio=0", "setpriv", "--bounding-set", "-sys_nice",
               "--inh-caps", "-sys_nice", str(BIN_DIR / "pointing_controller"),
               "--ros-args", "-p", "realtime_priority:=50"]
    node = node_processes.start("pointing_controller", command=command)
    assert node.wait(HANG_GUARD_S) == 2, node.output()
    errors = [line for line in node.output().splitlines() if "error:" in line]
    assert errors == ["pointing_controller: error: realtime_priority 50: the OS refused "
                      "SCHED_FIFO (Operation not permitted); grant CAP_SYS_NICE or raise the "
                      "rtprio limit (ulimit -r, /etc/security/limits.conf), or set "
                      "realtime_priority 0"], node.output()


def test_the_probe_says_why_the_os_refuses_a_priority():
    # 100 is beyond SCHED_FIFO's range on Linux (1-99): refused for everyone.
    assert fifo_refusal(100) == "the OS refused SCHED_FIFO 100 (Invalid argument)"
    reason = fifo_refusal(DEFAULT_REALTIME_PRIORITY)
    assert reason is None or reason.startswith("the OS refused SCHED_FIFO 50"), reason


def test_experiment_priority_as_asked_else_by_mode(capsys):
    assert realtime_priority(0, "realtime") == 0
    assert realtime_priority(20, "lockstep") == 20
    assert realtime_priority(None, "lockstep") == 0
    assert capsys.readouterr().out == ""                  # nothing to say
    permitted = fifo_refusal(DEFAULT_REALTIME_PRIORITY) is None
    assert realtime_priority(None, "realtime") == (DEFAULT_REALTIME_PRIORITY if permitted
                                                   else 0)
    said = capsys.readouterr().out
    assert said.count("\n") == 1 and ("SCHED_FIFO priority 50" in said) == permitted, said


@pytest.mark.skipif(not (shutil.which("setpriv") and shutil.which("prlimit")),
                    reason="needs util-linux setpriv and prlimit to withhold the permission")
def test_experiment_without_the_permission_runs_without_priority_and_says_why():
    code = ("from hexapod_vibration.tools.experiment import realtime_priority; "
            "print(realtime_priority(None, 'realtime'))")
    result = subprocess.run(["prlimit", "--rtprio=0", "setpriv", "--bounding-set", "-sys_nice",
                             "--inh-caps", "-sys_nice", sys.executable, "-c", code],
                            capture_output=True, text=True, timeout=HANG_GUARD_S, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        "experiment: realtime without real-time priority: the OS refused SCHED_FIFO 50 "
        "(Operation not permitted); in separate processes several times more samples may be "
        "late (docs/performance.md)", "0"], result.stdout
