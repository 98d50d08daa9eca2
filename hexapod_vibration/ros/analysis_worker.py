"""The notch controller's analysis worker: a process beside the realtime loop.

The analysis of a finished broadband identification costs ~0.8 s of CPU (G(f) from the
record, ~20 Nyquist tests, the mu policy; docs/performance.md). On the loop's thread it
holds the loop off for that long: in a realtime run through separate processes it was ~95 %
of the late commands. With ``identification_analysis: process`` the notch node hands those
computations to one worker process
(:mod:`~hexapod_vibration.core.control.supervisor.analysis_jobs`): the loop keeps its
deadline and the analysis takes as many samples as the worker needs.

The worker is started with the node, from its main thread, before the node's real-time
scheduling applies, and it puts itself back on the normal scheduler (a SCHED_FIFO worker
would starve the loops it is meant to spare). It ignores SIGINT (Ctrl-C stops the node,
which shuts it down) and dies with the node's process (``PR_SET_PDEATHSIG``), so no worker
outlives its node.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
from concurrent.futures import ProcessPoolExecutor

ANALYSIS_MODULES = (
    "hexapod_vibration.core.control.supervisor.identification",
    "hexapod_vibration.core.control.supervisor.rate_policy",
)
"""What the worker imports at start-up (the jobs' functions), not at its first job."""
_PR_SET_PDEATHSIG = 1


def _die_with(parent_pid: int) -> None:
    """Ask Linux to kill this process when its parent's creating thread ends."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):      # not Linux: the node's shutdown still ends it
        return
    if os.getppid() != parent_pid:         # the parent died before prctl
        os._exit(0)


def _start_worker(parent_pid: int) -> None:
    """The worker's initializer: normal scheduling, no SIGINT, death with the parent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    _die_with(parent_pid)
    import importlib
    for module in ANALYSIS_MODULES:
        importlib.import_module(module)


def _ready() -> bool:
    """The warm-up job: True once the worker has imported the analysis."""
    return True


def start_analysis_worker() -> ProcessPoolExecutor:
    """One spawned worker process, started now (call it before real-time scheduling).

    Shut it down with ``shutdown(wait=True, cancel_futures=True)`` when the node ends: not
    waiting leaves its queues' semaphores to the resource tracker, which complains.
    """
    worker = ProcessPoolExecutor(max_workers=1,
                                 mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_start_worker, initargs=(os.getpid(),))
    worker.submit(_ready)                   # spawns the process from this thread, now
    return worker
