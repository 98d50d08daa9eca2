"""Sweep throughput for ``hexapod_bench``: points per second with 1 and 2 Dask workers.

A fixed grid of short points (the Table 1 loop with one 40 Hz tone, 5.4 s simulated, each
with its own seed, so every point does the same work: the loop, its reference run without
control and its exact bound) runs
on a fresh ``LocalCluster`` per worker count. The clock runs from submitting the points to
the last result, after one warm-up point per worker (imports, first plant build). The
load average before and after is recorded, and the mean time each point took inside its
task (``mean_point_s``, a second measure): with free cores it stays the same for 2
workers as for 1 and the ratio is close to 2; on a shared machine the points slow down
by the other processes' share and the ratio tells as much about them as about Dask.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from hexapod_vibration.sweep import runner
from hexapod_vibration.sweep.grid import load_grid
from hexapod_vibration.sweep.outcome import FAILED

BENCH_SET = {
    "duration_s": 5.4, "identify_at_s": 0.2, "control_on_s": 4.4, "window_s": 1.0,
    "shaker.frequencies_hz": [40.0], "shaker.amplitudes_n": [80.0],
    "shaker.phases_rad": [0.0], "notch.tone_frequencies_hz": [40.0],
    "report_tones_hz": [40.0], "notch.settings.identification": "tones",
}
WORKER_COUNTS = (1, 2)


def _grid(points: int, folder: Path):
    mus = [round(0.001 + 0.0005 * k, 6) for k in range(points)]
    data = {"name": "bench_throughput", "base_scenario": "single_tone_harmonic",
            "set": BENCH_SET, "axes": {"notch.mu": mus}, "seeds": "per_point"}
    path = folder / "bench_throughput.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return load_grid(path)


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def sweep_throughput(quick: bool = False) -> dict[str, Any]:
    """Points per second with 1 and 2 workers, their ratio, and the load around it."""
    points = 4 if quick else 8
    with tempfile.TemporaryDirectory() as tmp:
        grid = _grid(points + max(WORKER_COUNTS), Path(tmp))
        warmup, timed = grid.points[points:], grid.points[:points]
        rates, walls, in_task, load_before = {}, {}, {}, _load()
        for workers in WORKER_COUNTS:
            client = runner.local_client(workers)
            try:
                list(runner.run_on_dask(client, warmup[:workers]))
                start = time.perf_counter()
                rows = [row for _, row in runner.run_on_dask(client, timed)]
                walls[str(workers)] = time.perf_counter() - start
            finally:
                runner.close_client(client)
            if any(r["status"] == FAILED for r in rows):
                raise RuntimeError("a throughput point failed: "
                                   + next(r["error"] for r in rows if r["status"] == FAILED))
            rates[str(workers)] = points / walls[str(workers)]
            in_task[str(workers)] = sum(r["elapsed_s"] for r in rows) / points
    return {"sweep_throughput": {
        "points": points, "simulated_s_per_point": BENCH_SET["duration_s"],
        "points_per_s": rates, "wall_s": walls, "mean_point_s": in_task,
        "ratio_2_over_1": rates["2"] / rates["1"],
        "cores_usable": runner.usable_cores(),
        "load_average_before": load_before, "load_average_after": _load()}}


def summary_lines(results: dict[str, Any]) -> list[str]:
    """Markdown lines for hexapod_bench's summary."""
    t = results["sweep_throughput"]
    rates = ", ".join(f"{w} worker{'s' if w != '1' else ''} {r:.3f}"
                      for w, r in t["points_per_s"].items())
    return ["", "## Sweep throughput (Dask LocalCluster, core loop points)", "",
            f"{t['points']} points of {t['simulated_s_per_point']:g} s simulated each "
            f"(loop, reference run without control, metrics, exact bound): points/s {rates}; "
            "2/1 ratio "
            f"{t['ratio_2_over_1']:.2f} on {t['cores_usable']} usable cores; mean time in a "
            f"task {', '.join(f'{w}: {v:.2f} s' for w, v in t['mean_point_s'].items())}; "
            "load average "
            f"{t['load_average_before']} before, {t['load_average_after']} after."]
