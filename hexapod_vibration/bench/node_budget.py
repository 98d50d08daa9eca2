"""The CPU budget of the loop's processes: CPU time per sample of each node, and where it goes.

Each set-up (:data:`BUDGET_SETUPS`: layout, clock mode, recorder, real-time priority, a
busy core beside the graph) runs the Table 1 graph for ``warmup_s`` then ``measure_s`` wall
seconds. Two independent readings of the same window:

- ``/proc/<pid>/stat`` of every process (user + system time, all threads; and the main
  thread's ``/proc/<pid>/task/<pid>/stat``), divided by the samples the driver advanced in
  the window (its ``sample`` on ``/diagnostics``): the cost per sample of each process;
- each node's own meter (``core/loop/cost_meter.py``, on ``/diagnostics`` as
  ``cpu_us_per_sample <stage>``, its last 1000-sample window): where the main thread's
  time goes (wait, take, decode, control law or plant, publish, report).

Realtime set-ups also give the loop's missed samples and latency (the driver's counts)
over the same window, which starts once the notch's identification is over (control in
force, or refused; at most ``settle_limit_s`` past the warm-up): the late commands of the
start, its identification's analysis above all, are counted apart (``bench/late_window.py``).
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hexapod_vibration.bench.late_window import LateWindow
from hexapod_vibration.core.loop.cost_meter import KEY_PREFIX
from hexapod_vibration.tools.processes import Child, spawn, spawn_module, stop_all

CLK_TCK = os.sysconf("SC_CLK_TCK")
NODES = ("pph_driver", "notch_controller", "pointing_controller", "pph_recorder")


@dataclass(frozen=True)
class BudgetSetup:
    """One measured set-up of the graph."""

    layout: str                 # "processes" (one per node) or "composed" (pph_graph)
    mode: str                   # "lockstep" or "realtime"
    recorder: bool = True
    priority: int = 0           # realtime_priority of the loop nodes (0 = normal)
    busy_core: bool = False     # a process spinning on one core beside the graph

    @property
    def key(self) -> str:
        """e.g. ``processes/realtime/recorder/fifo50/busy``."""
        parts = [self.layout, self.mode, "recorder" if self.recorder else "no recorder"]
        if self.priority:
            parts.append(f"fifo{self.priority}")
        if self.busy_core:
            parts.append("busy core")
        return "/".join(parts)


BUDGET_SETUPS = (
    BudgetSetup("processes", "lockstep"),
    BudgetSetup("processes", "realtime"),
    BudgetSetup("processes", "realtime", recorder=False),
    BudgetSetup("processes", "realtime", priority=50),
    BudgetSetup("processes", "realtime", recorder=False, priority=50),
    BudgetSetup("processes", "realtime", busy_core=True),
    BudgetSetup("processes", "realtime", priority=50, busy_core=True),
    BudgetSetup("composed", "lockstep"),
    BudgetSetup("composed", "realtime"),
)


def process_cpu_s(pid: int) -> tuple[float, float]:
    """(all threads, main thread) user + system CPU seconds of process ``pid``."""
    def ticks(path: str) -> int:
        fields = Path(path).read_text().rsplit(")", 1)[1].split()
        return int(fields[11]) + int(fields[12])
    return (ticks(f"/proc/{pid}/stat") / CLK_TCK,
            ticks(f"/proc/{pid}/task/{pid}/stat") / CLK_TCK)


def busy_core() -> Child:
    """A process spinning on one CPU (the other load of a 'busy core' set-up)."""
    return spawn("busy_core", [sys.executable, "-c", "while True:\n    pass"])


def start_graph(out: Path, params: Path, setup: BudgetSetup) -> dict[str, Child]:
    """The loop's processes (and the recorder) of ``setup``, by node name."""
    args = ["--ros-args", "--params-file", str(params)]
    tag = setup.key.replace("/", "_").replace(" ", "_")
    names = (("pph_graph",) if setup.layout == "composed"
             else ("notch_controller", "pointing_controller", "pph_driver"))
    children = {}
    if setup.recorder:
        bag = out / f"bag_{tag}"
        shutil.rmtree(bag, ignore_errors=True)          # the previous benchmark's bag
        children["pph_recorder"] = spawn_module(
            f"budget_recorder_{tag}", "hexapod_vibration.nodes.recorder",
            ["--ros-args", "-p", f"bag_path:={bag}"], out)
    for name in names:
        children[name] = spawn_module(f"budget_{name}_{tag}", f"hexapod_vibration.nodes.{name}",
                                      args, out)
    return children


def stage_costs(statuses: dict[str, dict[str, str]]) -> dict[str, dict[str, float]]:
    """Each node's meter (``cpu_us_per_sample <stage>``) from its /diagnostics values."""
    return {node: {key.removeprefix(KEY_PREFIX): float(value)
                   for key, value in values.items() if key.startswith(KEY_PREFIX)}
            for node, values in statuses.items()}


def cpu_per_sample(before: dict[str, tuple[float, float]], after: dict[str, tuple[float, float]],
                   samples: int) -> dict[str, dict[str, float]]:
    """CPU (us) per loop sample of each process over a window of ``samples`` samples."""
    per = 1e6 / max(samples, 1)
    return {name: {"process": (after[name][0] - before[name][0]) * per,
                   "main thread": (after[name][1] - before[name][1]) * per}
            for name in before if name in after}


def budget_summary_markdown(budget: dict[str, Any]) -> str:
    """The budget tables: us per sample per process, then each node's stages."""
    rows = ["| set-up | driver | notch | pointing | recorder | total | missed % | "
            "latency p99 ms |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for key, result in budget.items():
        cpu = result.get("cpu_us_per_sample", {})
        cells = [_us(cpu.get(name, {}).get("process")) for name in
                 ("pph_driver", "notch_controller", "pointing_controller", "pph_recorder")]
        if "pph_graph" in cpu:
            cells = [f"{_us(cpu['pph_graph'].get('process'))} (one process)", "", "",
                     cells[3]]
        total = sum(v.get("process", 0.0) for v in cpu.values())
        loop = result.get("loop", {})
        missed = loop.get("missed_fraction")
        rows.append(f"| {key} | " + " | ".join(cells) + f" | {_us(total)} | "
                    f"{'-' if missed is None else f'{100 * missed:.3f}'} | "
                    f"{loop.get('latency_ms_p99', '-')} |")
    return "\n".join(rows)


def stages_markdown(budget: dict[str, Any], key: str) -> str:
    """Where each node's time goes in one set-up (its meter's last window), us per sample."""
    rows = ["| node | stage | us per sample |", "|---|---|---:|"]
    for node, stages in budget.get(key, {}).get("stages", {}).items():
        for stage, value in sorted(stages.items(), key=lambda kv: -kv[1]):
            rows.append(f"| {node} | {stage} | {value:.1f} |")
    return "\n".join(rows)


def _us(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f}"


def measure(out: Path, params: Path, setup: BudgetSetup, warmup_s: float, measure_s: float,
            watch: Any, settle_limit_s: float = 0.0) -> dict[str, Any]:
    """The budget of one set-up (``watch``: a ``tools.graph_monitor.GraphMonitor``).

    The window starts after the warm-up, and once the notch's identification is over, at
    most ``settle_limit_s`` (s, wall) later.
    """
    load = busy_core() if setup.busy_core else None
    children = start_graph(out, params, setup)
    try:
        late = LateWindow(watch)
        _wait_until_running(children, watch, warmup_s)
        _wait_until_settled(children, watch, late, settle_limit_s)
        late.start_now()
        first = int(watch.driver.get("sample", 0))
        before = {name: process_cpu_s(child.pid) for name, child in children.items()}
        end = time.monotonic() + measure_s
        while time.monotonic() < end:
            _alive(children)
            watch.spin(0.2)
        after = {name: process_cpu_s(child.pid) for name, child in children.items()}
        samples = int(watch.driver.get("sample", 0)) - first
        statuses = {"pph_driver": watch.driver, "notch_controller": watch.notch,
                    "pointing_controller": watch.pointing, "pph_recorder": watch.recorder}
        return {"samples": samples, "wall_s": measure_s,
                "cpu_us_per_sample": cpu_per_sample(before, after, samples),
                "stages": stage_costs(statuses),
                "loop": _loop_stats(watch.driver, setup, late)}
    finally:
        # The driver first, the recorder last (as the experiment runner): a recorder stopped
        # while the loop still publishes drains for DRAIN_MAX_S (10 s) before it exits.
        stop_all(list(children.values())[::-1])
        if load is not None:
            stop_all([load])


def _loop_stats(driver: dict[str, str], setup: BudgetSetup, late: LateWindow
                ) -> dict[str, Any]:
    """Rate; realtime: late commands in the window and before it, latency p99 (ms)."""
    stats = {"rate_hz": float(driver.get("rate_hz", "nan"))}
    if setup.mode == "realtime":
        window = late.report()
        stats.update(missed_fraction=window["control_missed_fraction"],
                     missed_samples=window["control_late"],
                     settled=window["control_settled"],
                     samples_before=late.start[0], late_before=late.start[1],
                     latency_ms_p99=driver.get("latency_ms_p99"))
    return stats


def _wait_until_running(children: dict[str, Child], watch: Any, warmup_s: float) -> None:
    """Until the loop runs (handshake, discovery), then ``warmup_s`` more."""
    start = time.monotonic()
    while int(watch.driver.get("sample", 0)) <= 0:
        _alive(children)
        watch.spin(0.1)
        if time.monotonic() - start > 120.0:
            raise RuntimeError("the loop never started")
    end = time.monotonic() + warmup_s
    while time.monotonic() < end:
        _alive(children)
        watch.spin(0.2)


def _wait_until_settled(children: dict[str, Child], watch: Any, late: LateWindow,
                        limit_s: float) -> None:
    """Until the notch's identification is over (``late`` follows it), at most ``limit_s``."""
    end = time.monotonic() + limit_s
    while not late.follow() and time.monotonic() < end:
        _alive(children)
        watch.spin(0.2)


def _alive(children: dict[str, Child]) -> None:
    for child in children.values():
        if not child.alive():
            raise RuntimeError(f"{child.name} exited: {child.tail()}")
