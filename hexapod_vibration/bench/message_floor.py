"""The floor of the loop's message path: what four processes cost with nothing computed.

Runs :mod:`hexapod_vibration.bench.floor_nodes` (driver, notch, pointing, recorder, each
its own process; the real nodes' topics, QoS, wait sets and codec, no computation) in
lockstep and in realtime (and composed: driver and controllers as one process, as
``pph_graph``), and reports per process the CPU per sample (its own
``time.process_time`` over the samples after the warm-up), the lockstep speed and the
realtime late commands. Against the real graph's budget (``node_budget``) it separates what
the message path costs on this machine from what the nodes compute: the part no change to
the nodes' computation can remove.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from hexapod_vibration.bench.floor_nodes import COMPOSED, ROLES
from hexapod_vibration.tools.processes import Child, spawn_module, stop_all

FLOOR_RUNS = (("lockstep", True, 0, 20000, False), ("realtime", True, 0, 62000, False),
              ("realtime", False, 0, 62000, False), ("realtime", True, 50, 62000, False),
              ("lockstep", True, 0, 20000, True), ("lockstep", False, 0, 20000, True))
"""(mode, recorder, SCHED_FIFO priority, samples, composed) of every floor run (lockstep
about 10 s here; realtime 62 s: 60 s after the warm-up)."""
FLOOR_WARMUP = 2000
QUICK_SAMPLES = 4000


def run_floor(out: Path, mode: str, samples: int, warmup: int = FLOOR_WARMUP,
              command_delay: int | None = None, timeout_s: float = 600.0,
              env: dict[str, str] | None = None, recorder: bool = True,
              priority: int = 0, composed: bool = False) -> dict[str, Any]:
    """One floor run (``mode``: lockstep or realtime; ``recorder``: with one); its measurements.

    ``composed``: the driver and both controllers in one process (its CPU is the
    ``driver`` entry of the result), as ``pph_graph``.

    ``command_delay``: the loop's ``command_delay_samples`` (None: the experiment's, 2 in
    realtime and 0 in lockstep). ``priority``: SCHED_FIFO priority of the driver and
    controllers (0: none), as the nodes' ``realtime_priority`` (the recorder keeps normal
    scheduling).

    The processes' logs and result files go to ``out``; ``env``: their environment (None:
    this process's, whose ``ROS_DOMAIN_ID`` they share).

    Returns:
        ``{"cpu_us_per_sample": {role: us}, "total_us", "samples", "x_real_time",
        "latency_ms_p50", "latency_ms_p99", "late_fraction"}`` (the last in realtime only).

    Raises:
        RuntimeError: a process died or the driver did not finish in ``timeout_s``.
    """
    out.mkdir(parents=True, exist_ok=True)
    roles = [role for role in ((COMPOSED, "recorder") if composed else ROLES)
             if recorder or role != "recorder"]
    loop_role = COMPOSED if composed else "driver"
    results = {role: out / f"floor_{mode}_{role}.json" for role in roles}
    for path in results.values():
        path.unlink(missing_ok=True)
    common = ["--mode", mode, "--samples", str(samples), "--warmup", str(warmup),
              "--command-delay", str(_delay(mode) if command_delay is None else command_delay),
              "--priority", str(priority)]
    waits = ["--recorder"] if recorder else []        # the loop role holds sample 0 for it
    children = {role: spawn_module(f"floor_{mode}_{role}", "hexapod_vibration.bench.floor_nodes",
                                   [role, *common, *(waits if role == loop_role else []),
                                    "--result", str(results[role])], out, env=env)
                for role in reversed(roles)}
    try:
        _wait_for_driver(children, loop_role, timeout_s)
    finally:
        stop_all([child for role, child in children.items() if role != loop_role])
        stop_all([children[loop_role]])
    measured = {"driver" if role == COMPOSED else role: _read(path, children[role])
                for role, path in results.items()}
    return floor_summary(measured, mode)


def floor_summary(measured: dict[str, dict[str, float]], mode: str) -> dict[str, Any]:
    """CPU (us) per sample per role, their sum, lockstep speed, realtime late fraction."""
    per = {role: 1e6 * m["cpu_s"] / m["samples"] for role, m in measured.items()
           if m["samples"] > 0}
    driver = measured["driver"]
    result = {"cpu_us_per_sample": per, "total_us": sum(per.values()),
              "samples": driver["samples"],
              "x_real_time": driver["samples"] / driver["wall_s"] / 1000.0
              if driver["wall_s"] > 0 else None}
    result["latency_ms_p50"] = driver.get("latency_ms_p50")
    result["latency_ms_p99"] = driver.get("latency_ms_p99")
    if mode == "realtime":
        result["late_fraction"] = driver["late"] / max(driver["samples"], 1)
    return result


def measure_floor(out: Path, quick: bool) -> dict[str, Any]:
    """Every run of :data:`FLOOR_RUNS`, for results.json (``--quick``: short ones)."""
    floor = {}
    for mode, recorder, priority, samples, composed in FLOOR_RUNS:
        samples = QUICK_SAMPLES if quick else samples
        key = f"{mode}/{'recorder' if recorder else 'no recorder'}" + (
            f"/fifo{priority}" if priority else "") + ("/composed" if composed else "")
        print(f"message-path floor: {key}, {samples} samples ...", flush=True)
        try:
            floor[key] = run_floor(out, mode, samples, min(FLOOR_WARMUP, samples // 4),
                                   recorder=recorder, priority=priority, composed=composed)
        except RuntimeError as exc:
            floor[key] = {"failed": str(exc)}
    return floor


def floor_markdown(floor: dict[str, Any]) -> str:
    """The floor table: us of CPU per sample per process, speed, late commands."""
    rows = ["| message path alone | driver | notch | pointing | recorder | total | "
            "x real time | late % | latency p50 / p99 ms |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for mode, result in floor.items():
        if "failed" in result:
            rows.append(f"| {mode} | failed: {result['failed']} | | | | | | | |")
            continue
        cpu = result["cpu_us_per_sample"]
        cells = [f"{cpu[role]:.0f}" if role in cpu else "-" for role in ROLES]
        if mode.endswith(COMPOSED):
            cells[0] += " (one process)"            # the driver's cell: the whole process
        late = result.get("late_fraction")
        latency = " / ".join(_ms(result.get(k)) for k in ("latency_ms_p50", "latency_ms_p99"))
        rows.append(f"| {mode} | {' | '.join(cells)} | {result['total_us']:.0f} | "
                    f"{result['x_real_time']:.2f} | "
                    f"{'-' if late is None else f'{100 * late:.3f}'} | {latency} |")
    return "\n".join(rows)


def _delay(mode: str) -> int:
    """The experiment's command delay in ``mode`` (samples)."""
    from hexapod_vibration.tools.experiment_setup import REALTIME_COMMAND_DELAY_SAMPLES

    return REALTIME_COMMAND_DELAY_SAMPLES if mode == "realtime" else 0


def _ms(value: float | None) -> str:
    return "-" if value is None or value != value else f"{value:.2f}"


def _wait_for_driver(children: dict[str, Child], loop_role: str, timeout_s: float) -> None:
    """Until the driver's process (``loop_role``) exits (its samples done).

    Any other exit is an error.
    """
    end = time.monotonic() + timeout_s
    while children[loop_role].alive():
        for role, child in children.items():
            if role != loop_role and not child.alive():
                raise RuntimeError(f"floor {role} exited: {child.tail()}")
        if time.monotonic() > end:
            raise RuntimeError(f"the floor driver did not finish in {timeout_s:.0f} s")
        time.sleep(0.1)


def _read(path: Path, child: Child) -> dict[str, float]:
    """A floor process's result file."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise RuntimeError(f"{child.name} wrote no result ({exc}): {child.tail()}") from exc
