"""The machine's own 1 kHz wake-ups: how late a process that only sleeps wakes up.

Each of N processes sleeps to absolute deadlines one loop period apart (``time.sleep`` to
the next deadline, as the driver's realtime loop paces itself) and records how late it
woke; nothing else runs in it (no ROS, no work). What is left is what the OS scheduler, and
a virtual machine's hypervisor, give a 1 kHz process on this machine: a floor under the
missed samples of any realtime loop of separate processes here, whatever they compute.
The late fraction beyond the loop's budget (``command_delay_samples`` + 1 periods: a
controller that wakes later than that cannot answer in time) is the number to hold against
a missed-sample target. Like cyclictest, in Python (the nodes' language).
"""

from __future__ import annotations

import multiprocessing
import queue
import time
from typing import Any

import numpy as np

from hexapod_vibration.contract import SAMPLE_RATE_HZ
from hexapod_vibration.tools.experiment_setup import REALTIME_COMMAND_DELAY_SAMPLES

PERIOD_S = 1.0 / SAMPLE_RATE_HZ
"""The loop period (s)."""
BUDGET_MS = 1e3 * (REALTIME_COMMAND_DELAY_SAMPLES + 1) * PERIOD_S
"""The realtime experiment's budget (ms): a controller has d + 1 periods (command delay d)."""
LATE_MS = (1.0, 2.0, BUDGET_MS)
"""Lateness thresholds reported (ms); the last is the budget."""
WAKEUP_RUNS = (("1 process", 1, 0), ("4 processes", 4, 0),
               ("1 process, SCHED_FIFO 50", 1, 50), ("4 processes, SCHED_FIFO 50", 4, 50))
"""(label, processes, SCHED_FIFO priority (0: normal scheduling)) of every run: one
process alone, and as many as the graph has (driver, notch, pointing, recorder)."""
WAKEUP_S = 60.0
QUICK_WAKEUP_S = 1.0
START_S = 0.5
"""Wall time (s) from a process's start to its first deadline (all start together)."""


def sleep_lateness(deadlines: int, period_s: float = PERIOD_S) -> np.ndarray:
    """Lateness (s) of each of ``deadlines`` wake-ups ``period_s`` apart, from now + START_S."""
    late = np.empty(deadlines)
    start = time.perf_counter() + START_S
    clock, sleep = time.perf_counter, time.sleep
    for k in range(deadlines):
        deadline = start + k * period_s
        while (remaining := deadline - clock()) > 0.0:
            sleep(remaining)
        late[k] = clock() - deadline
    return late


def _sleeper(deadlines: int, priority: int, results: Any) -> None:
    """A child process: the priority, if any, then :func:`sleep_lateness` into ``results``."""
    from hexapod_vibration.ros.realtime import SchedulingRefused, set_fifo_priority

    try:
        if priority:
            set_fifo_priority(priority)
    except SchedulingRefused as exc:
        results.put(str(exc))
        return
    results.put(sleep_lateness(deadlines))


def measure_wakeups(processes: int, seconds: float, priority: int = 0) -> dict[str, Any]:
    """Run ``processes`` sleepers for ``seconds`` at once; :func:`wakeup_summary` of them.

    ``priority``: SCHED_FIFO priority of each (0: normal scheduling). Where the OS refuses
    it: ``{"refused": reason}``.
    """
    context = multiprocessing.get_context("spawn")
    results = context.Queue()
    deadlines = int(round(seconds / PERIOD_S))
    children = [context.Process(target=_sleeper, args=(deadlines, priority, results),
                                daemon=True) for _ in range(processes)]
    for child in children:
        child.start()
    try:
        got = [results.get(timeout=seconds + 60.0) for _ in children]
    except queue.Empty:
        return {"failed": f"a sleeper gave no result within {seconds + 60.0:.0f} s"}
    finally:
        for child in children:
            child.join(timeout=5.0)
            if child.is_alive():
                child.kill()
    refused = [g for g in got if isinstance(g, str)]
    if refused:
        return {"refused": refused[0]}
    return wakeup_summary(got)


def wakeup_summary(lateness_s: list[np.ndarray]) -> dict[str, Any]:
    """Late fractions beyond each of LATE_MS, pooled and at any process; p99 and max (ms).

    ``late_fraction[t]``: of all wake-ups; ``any_late_fraction[t]``: of the deadlines, those
    at which at least one process was later than t (a loop of these processes needs all).
    Each process counts its deadlines from its own start, so the k-th deadlines of two
    processes lie apart by their start-up skew (tens of ms), as a graph's nodes do not share
    deadlines either.
    """
    late_ms = [1e3 * np.asarray(x) for x in lateness_s]
    pooled = np.concatenate(late_ms)
    common = min(x.size for x in late_ms)
    stacked = np.vstack([x[:common] for x in late_ms])
    return {
        "processes": len(late_ms), "wakeups": int(pooled.size),
        "late_fraction": {f"{t:g}": float(np.mean(pooled > t)) for t in LATE_MS},
        "any_late_fraction": {f"{t:g}": float(np.mean(np.any(stacked > t, axis=0)))
                              for t in LATE_MS},
        "p99_ms": float(np.percentile(pooled, 99)), "max_ms": float(pooled.max()),
    }


def measure_all_wakeups(quick: bool) -> dict[str, Any]:
    """Every run of :data:`WAKEUP_RUNS`, for results.json (``--quick``: 1 s each)."""
    seconds = QUICK_WAKEUP_S if quick else WAKEUP_S
    measured = {}
    for label, processes, priority in WAKEUP_RUNS:
        print(f"1 kHz wake-ups: {label}, {seconds:g} s ...", flush=True)
        measured[label] = measure_wakeups(processes, seconds, priority)
    return measured


def wakeup_markdown(measured: dict[str, Any]) -> str:
    """The wake-up table: % of wake-ups later than each threshold, p99 and max."""
    head = " | ".join(f"> {t:g} ms %" for t in LATE_MS)
    rows = [f"| sleepers | wake-ups | {head} | any process > {LATE_MS[-1]:g} ms % | "
            "p99 / max ms |", "|---|---:|" + "---:|" * (len(LATE_MS) + 2)]
    for label, result in measured.items():
        if "late_fraction" not in result:
            reason = result.get("refused") or result.get("failed")
            rows.append(f"| {label} | {reason} |" + " |" * (len(LATE_MS) + 2))
            continue
        cells = " | ".join(f"{100 * result['late_fraction'][f'{t:g}']:.3f}" for t in LATE_MS)
        worst = 100 * result["any_late_fraction"][f"{LATE_MS[-1]:g}"]
        rows.append(f"| {label} | {result['wakeups']} | {cells} | {worst:.3f} | "
                    f"{result['p99_ms']:.2f} / {result['max_ms']:.1f} |")
    return "\n".join(rows)
