"""The ROS loop benchmark: the 1 kHz graph in realtime and lockstep, per executor.

Runs the three nodes as processes (as the experiment runner does, without the recorder)
on a private ROS domain, with the Table 1 shaker and notch settings, and reads the
driver's own measurements from ``/diagnostics``:

- realtime: achieved rate, missed samples (a command of sample n not back by the end of
  sample n), period between sample publications (p50/p99/max) and accel-to-notch-command
  latency (p50/p99/max), for ``duration_s`` of wall time (60 s, 10 s with ``--quick``);
- lockstep: simulated seconds per wall second (the speed-up over real time);
- both for each executor that works (SingleThreaded and rclpy's EventsExecutor; an
  executor that stalls is reported as such, not hidden).
"""

from __future__ import annotations

import os
import random
import time
from pathlib import Path
from typing import Any

from hexapod_vibration.core.scenario import load_scenario
from hexapod_vibration.experiment import (
    Child,
    ExperimentError,
    Supervisor,
    node_parameters,
    start_child,
    stop_children,
)
from hexapod_vibration.paths import scenario_path

EXECUTORS = ("single_threaded", "events")
STALL_S = 20.0


def _write_params(out: Path, mode: str, executor: str) -> Path:
    import yaml

    scenario = load_scenario(scenario_path("single_tone_harmonic"))
    params = node_parameters(scenario, mode)
    for node in params.values():
        node["ros__parameters"]["executor"] = executor
    params["pph_driver"]["ros__parameters"]["hold_at_time_s"] = -1.0
    params["notch_controller"]["ros__parameters"]["enabled"] = True
    path = out / f"bench_{mode}_{executor}.yaml"
    path.write_text(yaml.safe_dump(params))
    return path


def _start_graph(out: Path, mode: str, executor: str, composed: bool = False
                 ) -> list[Child]:
    """The driver and both controllers: three processes, or one (``pph_graph``)."""
    common = ["--params-file", str(_write_params(out, mode, executor))]
    tag = f"{mode}_{executor}"
    if composed:
        return [start_child(f"bench_pph_graph_{tag}", "hexapod_vibration.pph_graph", common,
                            out)]
    children = [start_child(f"bench_{name}_{tag}", f"hexapod_vibration.{name}", common, out)
                for name in ("notch_controller", "pointing_controller")]
    children.append(start_child(f"bench_pph_driver_{tag}", "hexapod_vibration.pph_driver",
                                common, out))
    return children


def _run(out: Path, mode: str, executor: str, wall_s: float) -> dict[str, Any]:
    """One configuration; returns the driver's last diagnostics (floats) or a stall note."""
    children = _start_graph(out, mode, executor)
    sup = Supervisor(watch_clock=False)
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
            if sup.sim_time_s > last_sim:
                last_sim, last_progress = sup.sim_time_s, time.monotonic()
            elif time.monotonic() - last_progress > STALL_S:
                return {"stalled": True, "sim_time_s": sup.sim_time_s}
        wall = time.monotonic() - t0_wall
        sim = sup.sim_time_s - t0_sim
        stats = {k: _number(v) for k, v in sup.driver.items()}
        stats["measured_sim_s_per_wall_s"] = sim / wall
        stats["wall_s"] = wall
        return stats
    finally:
        sup.close()
        stop_children(children)


def _alive(children: list[Child]) -> None:
    for child in children:
        if not child.alive():
            raise ExperimentError(f"{child.name} exited: {child.tail()}")


def _number(text: str) -> Any:
    try:
        return float(text)
    except ValueError:
        return text


def _realtime_block(stats: dict[str, Any], executor: str, wall_s: float) -> dict[str, Any]:
    if stats.get("stalled"):
        return {"executor": executor, "stalled": True}
    samples = stats.get("samples", 0.0) or 1.0
    return {"executor": executor, "duration_s": round(stats.get("wall_s", wall_s), 2),
            "rate_hz": stats.get("rate_hz"),
            "missed_fraction": stats.get("late_commands", 0.0) / samples,
            "missed_samples": stats.get("late_commands"),
            "period_ms_p50": stats.get("period_ms_p50"),
            "period_ms_p99": stats.get("period_ms_p99"),
            "period_ms_max": stats.get("period_ms_max"),
            "latency_ms_p50": stats.get("latency_ms_p50"),
            "latency_ms_p99": stats.get("latency_ms_p99"),
            "latency_ms_max": stats.get("latency_ms_max")}


def ros_loop_benchmark(out_dir: Path, quick: bool) -> dict[str, Any]:
    """Realtime and lockstep measurements of the ROS graph; keys for results.json."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if "ROS_DOMAIN_ID" not in os.environ:
        os.environ["ROS_DOMAIN_ID"] = str(random.randint(120, 200))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    realtime_s = 10.0 if quick else 60.0
    lockstep_s = 8.0 if quick else 20.0
    per_executor: dict[str, Any] = {}
    for executor in EXECUTORS:
        print(f"ROS loop: {executor}, realtime {realtime_s:g} s ...", flush=True)
        realtime = _realtime_block(_run(out, "realtime", executor, realtime_s), executor,
                                   realtime_s)
        print(f"ROS loop: {executor}, lockstep {lockstep_s:g} s ...", flush=True)
        lockstep = _run(out, "lockstep", executor, lockstep_s)
        per_executor[executor] = {
            "realtime": realtime,
            "lockstep": {"stalled": True} if lockstep.get("stalled") else {
                "speedup": lockstep["measured_sim_s_per_wall_s"],
                "rate_hz": lockstep.get("rate_hz"),
                "latency_ms_p50": lockstep.get("latency_ms_p50"),
                "timeouts": lockstep.get("timeouts")}}
    best = per_executor["single_threaded"]
    return {"realtime": best["realtime"],
            "lockstep_speedup": best["lockstep"].get("speedup"),
            "executors": per_executor,
            "ros_domain_id": int(os.environ["ROS_DOMAIN_ID"])}
