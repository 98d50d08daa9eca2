"""Real-time scheduling of a node's process: SCHED_FIFO priority and CPU affinity.

The 1 kHz nodes take two read-only parameters, as ros2_control's ``controller_manager`` does
(``thread_priority``, ``cpu_affinity``): ``realtime_priority`` (1-98 runs every thread of the
process, the node's loop and the DDS transport's threads, under SCHED_FIFO at that priority;
0 leaves the normal scheduler) and ``cpu_affinity`` (the CPUs the process may run on; empty:
all it may use now). Both apply once the node is built, before its loop starts. Where the
OS does not permit them (no CAP_SYS_NICE and an rtprio limit below the priority, a CPU the
process may not use) the node refuses to start with the reason in one line: a user who asked
for real-time scheduling never gets a loop that silently runs without it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence

DEFAULT_REALTIME_PRIORITY = 50
"""The SCHED_FIFO priority ``experiment --realtime`` gives the loop's nodes where the OS
permits it (ros2_control's ``controller_manager`` ``thread_priority`` default): in separate
processes it cut the samples late from 8.6-14.3 % to 2.1-3.4 % on a 2-core machine
(docs/performance.md)."""

_PROBE = """import os, sys
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param({priority}))
except OSError as exc:
    sys.exit(exc.strerror or type(exc).__name__)
"""


class SchedulingRefused(ValueError):
    """The OS does not permit the requested priority or affinity."""


def process_threads() -> list[int]:
    """The thread ids of this process."""
    return sorted(int(tid) for tid in os.listdir("/proc/self/task"))


def set_cpu_affinity(cpus: Sequence[int]) -> set[int]:
    """Restrict every thread of this process to ``cpus``; the set applied.

    Raises:
        SchedulingRefused: A CPU this process may not run on.
    """
    allowed = os.sched_getaffinity(0)
    wanted = set(cpus)
    if not wanted <= allowed:
        raise SchedulingRefused(f"cpu_affinity {sorted(wanted)}: this process may run on CPUs "
                                f"{sorted(allowed)} only")
    for tid in process_threads():
        _ignore_gone(os.sched_setaffinity, tid, wanted)
    return wanted


def set_fifo_priority(priority: int) -> None:
    """Run every thread of this process under SCHED_FIFO at ``priority`` (1-98).

    Raises:
        SchedulingRefused: The OS refused (no CAP_SYS_NICE, rtprio limit too low).
    """
    param = os.sched_param(priority)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, param)
    except PermissionError as exc:
        raise SchedulingRefused(
            f"realtime_priority {priority}: the OS refused SCHED_FIFO ({exc.strerror}); "
            "grant CAP_SYS_NICE or raise the rtprio limit (ulimit -r, "
            "/etc/security/limits.conf), or set realtime_priority 0") from None
    for tid in process_threads():
        _ignore_gone(os.sched_setscheduler, tid, os.SCHED_FIFO, param)


def fifo_refusal(priority: int) -> str | None:
    """Why a process of this user may not run under SCHED_FIFO at ``priority``; None if it may.

    Asked of a short-lived child process (about 30 ms), so this process keeps its scheduling.
    """
    try:
        probe = subprocess.run([sys.executable, "-c", _PROBE.format(priority=int(priority))],
                               capture_output=True, text=True, timeout=30.0, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"the SCHED_FIFO probe did not run ({exc})"
    if probe.returncode == 0:
        return None
    return f"the OS refused SCHED_FIFO {priority} ({probe.stderr.strip() or probe.returncode})"


def apply_scheduling(priority: int, cpus: Sequence[int]) -> str:
    """Apply ``cpu_affinity`` then ``realtime_priority``; what was applied, in words.

    Raises:
        SchedulingRefused: The OS does not permit one of them (nothing more is changed).
    """
    applied = []
    if cpus:
        applied.append(f"CPUs {sorted(set_cpu_affinity(cpus))}")
    if priority > 0:
        set_fifo_priority(priority)
        applied.append(f"SCHED_FIFO priority {priority}")
    return ", ".join(applied)


def _ignore_gone(call, tid: int, *args) -> None:
    """``call(tid, *args)`` for a thread that may have ended meanwhile."""
    try:
        call(tid, *args)
    except ProcessLookupError:
        pass
