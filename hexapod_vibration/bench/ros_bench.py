"""The ROS loop benchmark: the 1 kHz graph in realtime and lockstep, per layout and executor.

Runs the driver and both controllers (as the experiment runner does, without the recorder)
on a private ROS domain, with the Table 1 shaker and notch settings, and reads the
driver's own measurements from ``/diagnostics``:

- realtime: achieved rate, missed samples (a command of sample n not back by the end of
  sample n), period between sample publications (p50/p99/max) and accel-to-notch-command
  latency (p50/p99/max), for ``duration_s`` of wall time;
- lockstep: simulated seconds per wall second (the speed-up over real time).

Configurations (:data:`CONFIGURATIONS`): the two layouts (``composed``: one ``pph_graph``
process; ``processes``: three processes) with the default ``waitset`` executor, for 60 s
realtime each, and rclpy's SingleThreadedExecutor and
EventsExecutor in the three-process layout for a shorter comparison (an executor that
stalls is reported as such, not hidden). The headline ``realtime`` and
``lockstep_speedup`` keys are those of the first configuration, ``composed/waitset``.
"""

from __future__ import annotations

import math
import os
import random
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hexapod_vibration.bench.above_floor import above_floor_markdown
from hexapod_vibration.bench.late_window import LateWindow
from hexapod_vibration.bench.message_floor import floor_markdown, measure_floor
from hexapod_vibration.bench.node_budget import (
    BUDGET_SETUPS,
    budget_summary_markdown,
    measure,
    stages_markdown,
)
from hexapod_vibration.bench.wakeup_lateness import measure_all_wakeups, wakeup_markdown
from hexapod_vibration.contract import SAMPLE_RATE_HZ
from hexapod_vibration.core.sim.scenario import load_scenario
from hexapod_vibration.paths import scenario_path
from hexapod_vibration.tools.experiment_setup import node_parameters
from hexapod_vibration.tools.graph_monitor import ExperimentError, GraphMonitor
from hexapod_vibration.tools.processes import Child, spawn_module, stop_all

STALL_S = 20.0
DESCRIPTIONS = {
    "composed": "pph_graph: driver and controllers in one process and thread",
    "processes": "pph_driver, notch_controller, pointing_controller as three processes",
}


def _write_params(out: Path, mode: str, executor: str, priority: int = 0) -> Path:
    import yaml

    scenario = load_scenario(scenario_path("single_tone_harmonic"))
    params = node_parameters(scenario, mode)
    for node in params.values():
        node["ros__parameters"]["executor"] = executor
        node["ros__parameters"]["realtime_priority"] = priority
    params["pph_driver"]["ros__parameters"]["hold_at_time_s"] = -1.0
    params["notch_controller"]["ros__parameters"]["enabled"] = True
    path = out / f"bench_{mode}_{executor}_{priority}.yaml"
    path.write_text(yaml.safe_dump(params))
    return path


def _start_graph(out: Path, mode: str, executor: str, composed: bool
                 ) -> list[Child]:
    """The driver and both controllers: three processes, or one (``pph_graph``)."""
    common = ["--ros-args", "--params-file", str(_write_params(out, mode, executor))]
    tag = f"{mode}_{executor}"
    names = ("pph_graph",) if composed else ("notch_controller", "pointing_controller",
                                             "pph_driver")
    # tools/processes: every child dies with the benchmark, even if it is killed.
    return [spawn_module(f"bench_{name}_{tag}", f"hexapod_vibration.nodes.{name}", common, out)
            for name in names]


def _run(out: Path, mode: str, executor: str, wall_s: float, composed: bool
         ) -> dict[str, Any]:
    """One run; returns the driver's last diagnostics (floats) or a stall note."""
    children = _start_graph(out, mode, executor, composed)
    sup = GraphMonitor()
    late = LateWindow(sup)
    try:
        start = time.monotonic()
        while sup.sim_time_s < 0.0:           # handshake / discovery
            _alive(children)
            sup.spin(0.1)
            if time.monotonic() - start > 60.0:
                raise ExperimentError("the loop never started")
        t0_wall, t0_sim = time.monotonic(), sup.sim_time_s
        last_progress, last_sim = time.monotonic(), sup.sim_time_s
        while time.monotonic() - t0_wall < wall_s:
            _alive(children)
            sup.spin(0.2)
            late.follow()
            if sup.sim_time_s > last_sim:
                last_sim, last_progress = sup.sim_time_s, time.monotonic()
            elif time.monotonic() - last_progress > STALL_S:
                return {"stalled": True, "sim_time_s": sup.sim_time_s}
        wall = time.monotonic() - t0_wall
        sim = sup.sim_time_s - t0_sim
        stats = {k: _number(v) for k, v in sup.driver.items()}
        stats["measured_sim_s_per_wall_s"] = sim / wall
        stats["wall_s"] = wall
        stats.update(late.report())
        return stats
    finally:
        sup.close()
        stop_all(children)


def _alive(children: list[Child]) -> None:
    for child in children:
        if not child.alive():
            raise ExperimentError(f"{child.name} exited: {child.tail()}")


def _number(text: str) -> Any:
    try:
        return float(text)
    except ValueError:
        return text


def _realtime_block(stats: dict[str, Any], config: LoopConfiguration, wall_s: float
                    ) -> dict[str, Any]:
    executor = f"{config.executor} ({DESCRIPTIONS[config.layout]})"
    if stats.get("stalled"):
        return {"executor": executor, "stalled": True}
    samples = stats.get("samples", 0.0) or 1.0
    return {"executor": executor, "duration_s": round(stats.get("wall_s", wall_s), 2),
            "rate_hz": stats.get("rate_hz"),
            "missed_fraction": stats.get("late_commands", 0.0) / samples,
            "missed_samples": stats.get("late_commands"),
            # with control in force (from the end of the notch's identification)
            "control_missed_fraction": stats.get("control_missed_fraction"),
            "control_missed_samples": stats.get("control_late"),
            "control_samples": stats.get("control_samples"),
            "period_ms_p50": stats.get("period_ms_p50"),
            "period_ms_p99": stats.get("period_ms_p99"),
            "period_ms_max": stats.get("period_ms_max"),
            "latency_ms_p50": stats.get("latency_ms_p50"),
            "latency_ms_p99": stats.get("latency_ms_p99"),
            "latency_ms_max": stats.get("latency_ms_max")}


@dataclass(frozen=True)
class LoopConfiguration:
    """One measured set-up of the loop."""

    layout: str            # "composed" (pph_graph) or "processes"
    executor: str          # hexapod_vibration.ros.executors.EXECUTORS
    realtime_s: float      # wall seconds of the realtime run (full benchmark)
    lockstep_s: float      # wall seconds of the lockstep run (full benchmark)

    @property
    def key(self) -> str:
        """``layout/executor``."""
        return f"{self.layout}/{self.executor}"


CONFIGURATIONS = (
    LoopConfiguration("composed", "waitset", 60.0, 20.0),
    LoopConfiguration("processes", "waitset", 60.0, 20.0),
    LoopConfiguration("processes", "single_threaded", 20.0, 10.0),
    LoopConfiguration("processes", "events", 20.0, 10.0),
)
QUICK_S = (10.0, 5.0)
"""Realtime and lockstep wall seconds of every configuration with ``--quick``."""


def measure_configuration(out: Path, config: LoopConfiguration, quick: bool
                          ) -> dict[str, Any]:
    """Realtime and lockstep results of one configuration."""
    realtime_s, lockstep_s = QUICK_S if quick else (config.realtime_s, config.lockstep_s)
    composed = config.layout == "composed"
    print(f"ROS loop: {config.key}, realtime {realtime_s:g} s ...", flush=True)
    realtime = _realtime_block(_run(out, "realtime", config.executor, realtime_s, composed),
                               config, realtime_s)
    print(f"ROS loop: {config.key}, lockstep {lockstep_s:g} s ...", flush=True)
    lockstep = _run(out, "lockstep", config.executor, lockstep_s, composed)
    return {"realtime": realtime,
            "lockstep": {"stalled": True} if lockstep.get("stalled") else {
                # The driver's own count: samples per wall second since sample 0.
                "speedup": lockstep.get("rate_hz", float("nan")) / SAMPLE_RATE_HZ,
                "rate_hz": lockstep.get("rate_hz"),
                "latency_ms_p50": lockstep.get("latency_ms_p50"),
                "latency_ms_p99": lockstep.get("latency_ms_p99"),
                "timeouts": lockstep.get("timeouts")}}


LOG_DIR = "logs"
"""Sub-folder of the output folder for the nodes' logs and parameter files (bench/logs is
not tracked: only bench/results.json and bench/summary.md are)."""


def ros_loop_benchmark(out_dir: Path, quick: bool) -> dict[str, Any]:
    """Realtime and lockstep measurements of the ROS graph; keys for results.json.

    The nodes' logs and parameter files go to ``out_dir/logs``.
    """
    out = Path(out_dir) / LOG_DIR
    out.mkdir(parents=True, exist_ok=True)
    if "ROS_DOMAIN_ID" not in os.environ:
        os.environ["ROS_DOMAIN_ID"] = str(random.randint(120, 200))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    loops = {c.key: measure_configuration(out, c, quick) for c in CONFIGURATIONS}
    best = loops[CONFIGURATIONS[0].key]
    return {"realtime": best["realtime"],
            "lockstep_speedup": best["lockstep"].get("speedup"),
            "loops": loops, "budget": measure_budget(out, quick),
            "floor": measure_floor(out, quick), "wakeups": measure_all_wakeups(quick),
            "ros_domain_id": int(os.environ["ROS_DOMAIN_ID"])}


BUDGET_S = (15.0, 30.0)
"""Warm-up (past the 10 s identification: control on) and measured wall seconds of every
budget set-up; ``--quick``: QUICK_BUDGET_S."""
QUICK_BUDGET_S = (3.0, 4.0)
SETTLE_LIMIT_S = 30.0
"""Longest wait (s, wall) past the warm-up for the notch's identification to be over before
a budget window starts (``--quick``: none)."""


def measure_budget(out: Path, quick: bool) -> dict[str, Any]:
    """The CPU budget of every set-up of ``node_budget.BUDGET_SETUPS``."""
    warmup_s, measure_s = QUICK_BUDGET_S if quick else BUDGET_S
    budget = {}
    for setup in BUDGET_SETUPS:
        print(f"CPU budget: {setup.key}, {warmup_s:g} + {measure_s:g} s ...", flush=True)
        watch = GraphMonitor()
        try:
            params = _write_params(out, setup.mode, "waitset", setup.priority)
            budget[setup.key] = measure(out, params, setup, warmup_s, measure_s, watch,
                                        0.0 if quick else SETTLE_LIMIT_S)
        except (RuntimeError, ExperimentError) as exc:
            budget[setup.key] = {"failed": str(exc)}
        finally:
            watch.close()
    return budget


def _control_missed(rt: dict[str, Any]) -> str:
    """``%`` of the samples late with control in force, and of how many; '-' if none."""
    fraction, samples = rt.get("control_missed_fraction"), rt.get("control_samples")
    if fraction is None or not samples:
        return "-"
    return f"{_num(100.0 * fraction, 3)} of {samples:.0f}"


def ros_summary_markdown(results: dict[str, Any]) -> str:
    """The ROS loop section of the benchmark summary (a Markdown table)."""
    rows = ["| layout/executor | realtime s | rate Hz | missed % | missed %, control on | "
            "period p99 ms | latency p50 / p99 / max ms | lockstep x real time |",
            "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for key, loop in results.get("loops", {}).items():
        rt, ls = loop["realtime"], loop["lockstep"]
        lockstep = "stalled" if ls.get("stalled") else _num(ls.get("speedup"), 2)
        if rt.get("stalled"):
            rows.append(f"| {key} | stalled | | | | | | {lockstep} |")
            continue
        latency = " / ".join(_num(rt.get(k), 2) for k in
                             ("latency_ms_p50", "latency_ms_p99", "latency_ms_max"))
        rows.append(f"| {key} | {_num(rt.get('duration_s'), 1)} | {_num(rt.get('rate_hz'), 2)}"
                    f" | {_num(100.0 * rt.get('missed_fraction', float('nan')), 3)}"
                    f" | {_control_missed(rt)}"
                    f" | {_num(rt.get('period_ms_p99'), 2)} | {latency} | {lockstep} |")
    budget = results.get("budget")
    if budget:
        rows += ["", "### CPU budget per process (us of CPU per loop sample, /proc over the "
                 "measured window; Table 1 graph, waitset)", "", budget_summary_markdown(budget)]
        for key in (BUDGET_SETUPS[0].key, BUDGET_SETUPS[1].key):
            rows += ["", f"Where the main threads' time goes, {key} (each node's meter, last "
                     "1000 samples):", "", stages_markdown(budget, key)]
    floor = results.get("floor")
    if floor:
        rows += ["", "### The message path alone (bench/floor_nodes.py: the same four "
                 "processes, topics, QoS, wait sets and codec, nothing computed; each "
                 "process's CPU per sample after the warm-up)", "", floor_markdown(floor)]
        if budget:
            rows += ["", "### What the nodes add to the message path (bench/above_floor.py: the "
                     "budget's processes/lockstep/recorder CPU minus the message path's alone, "
                     "us per sample, this run)", "", above_floor_markdown(budget, floor)]
    wakeups = results.get("wakeups")
    if wakeups:
        rows += ["", "### The machine's 1 kHz wake-ups (bench/wakeup_lateness.py: processes "
                 "that only sleep to deadlines 1 ms apart, no ROS; % of wake-ups later than "
                 "each threshold)", "", wakeup_markdown(wakeups)]
    return "\n".join(rows)


def _num(value: Any, digits: int) -> str:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return "-"
    return "-" if math.isnan(number) else f"{number:.{digits}f}"
