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
from collections.abc import Sequence


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
