"""``soak``: a long lockstep run with a drifting disturbance; memory, divergence, warnings.

``soak [--scenario NAME] [--duration S] [--out DIR] [--rss-every S] [--composed]``

Starts the driver and both controllers (three processes, or ``pph_graph`` with
``--composed``) with the scenario's parameters (``config/scenarios/soak_drift.yaml`` by
default: the Table 1 shaker drifting +-0.2 Hz over 10 minutes, the notch at 40 and 80 Hz;
any scenario works, e.g. one with tracking once it exists), switches control on at the
scenario's ``control_on_s`` and runs ``--duration`` seconds of simulated time in lockstep.
No recorder (an hour is ~4 GB of bag); instead, while it runs:

- the resident memory (``VmRSS`` of ``/proc/<pid>/status``) of every process, this one
  included, every ``--rss-every`` seconds of wall time;
- the top plate's z acceleration RMS per 10 s of samples, from ``/pph/accel`` (a
  best-effort subscription: the lockstep loop never waits for it), in dB re 1 g;
- the driver's and the notch's ``/diagnostics`` (lockstep timeouts, missed samples,
  invalid messages, the notch's state), and every ``[WARN]``/``[ERROR]`` line the
  processes log.

Memory growth is given two ways: the slope of a least-squares line through the samples
after the warm-up (the first 10 % of the run, at least 60 s), and the difference of the
medians of the first and last tenth of those samples over the time between them; both in
MB per hour of wall time and per hour of simulated time. Divergence: the last window's
level against the best controlled one, and against the uncontrolled level. Writes
``DIR/soak.json`` and ``DIR/rss.csv`` (atomically) and prints a summary; exit 0 when the
soak's criteria hold (growth under 5 MB/hour, no divergence, no warning), 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hexapod_vibration import cli
from hexapod_vibration.contract import InvalidStrutMessage
from hexapod_vibration.paths import scenario_path
from hexapod_vibration.tools import outputs
from hexapod_vibration.tools.experiment_setup import params_file_text
from hexapod_vibration.tools.graph_monitor import GraphMonitor
from hexapod_vibration.tools.processes import Child, spawn_module, stop_all

DEFAULT_SCENARIO = "soak_drift"
GROWTH_LIMIT_MB_PER_H = 5.0
DIVERGENCE_LIMIT_DB = 3.0
"""The last window more than this above the best controlled one counts as divergence."""
LEVEL_WINDOW_SAMPLES = 10_000
WARMUP_FRACTION = 0.1
WARMUP_MIN_S = 60.0


def build_parser() -> argparse.ArgumentParser:
    """Command line of ``soak``."""
    parser = cli.ArgumentParser(prog="soak", description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO,
                        help=f"scenario name or YAML path (default {DEFAULT_SCENARIO})")
    parser.add_argument("--duration", type=cli.duration_s, default=3600.0, metavar="S",
                        help="simulated seconds of lockstep (default 3600)")
    parser.add_argument("--out", type=cli.output_dir, default=Path("out/soak"),
                        help="output directory (default out/soak)")
    parser.add_argument("--rss-every", type=cli.number(0.5, 600.0, "s"), default=10.0,
                        metavar="S", help="memory sampling period (s of wall time)")
    parser.add_argument("--composed", action="store_true",
                        help="driver and controllers in one process (pph_graph)")
    return parser


@dataclass
class Samples:
    """What the soak measured."""

    rss: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    """Per process: (wall s, sim s, RSS MB)."""
    levels: list[tuple[float, float]] = field(default_factory=list)
    """(sim s at the window's end, z-acceleration RMS dB re 1 g)."""


def rss_mb(pid: int) -> float | None:
    """Resident set size (MB) of a process, or None if it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def growth_mb_per_h(points: list[tuple[float, float]]) -> tuple[float, float]:
    """Memory growth (MB/hour) of (time s, MB) points: least-squares slope, median difference."""
    if len(points) < 4:
        return float("nan"), float("nan")
    t = [p[0] for p in points]
    m = [p[1] for p in points]
    t_mean, m_mean = statistics.fmean(t), statistics.fmean(m)
    var = sum((x - t_mean) ** 2 for x in t)
    slope = sum((x - t_mean) * (y - m_mean) for x, y in zip(t, m, strict=True)) / var
    k = max(len(points) // 10, 2)
    span = statistics.median(t[-k:]) - statistics.median(t[:k])
    medians = (statistics.median(m[-k:]) - statistics.median(m[:k])) / span if span else \
        float("nan")
    return slope * 3600.0, medians * 3600.0


class AccelLevel:
    """z-axis acceleration RMS per window of samples, from a best-effort subscription."""

    def __init__(self, node: Any, samples: Samples) -> None:
        """Subscribe (raw bytes, best effort) to ``/pph/accel``."""
        import numpy as np
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from std_msgs.msg import Float64MultiArray

        from hexapod_vibration.core.model.geometry import CubicHexapodGeometry

        self._np = np
        self._z_row = np.linalg.inv(CubicHexapodGeometry().top_jacobian)[2]
        self.samples = samples
        self._window: dict[int, float] = {}
        self._current = -1
        qos = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT,
                         history=HistoryPolicy.KEEP_LAST, depth=1000)
        node.create_subscription(Float64MultiArray, "/pph/accel", self._on_accel, qos,
                                 raw=True)

    def _on_accel(self, data: bytes) -> None:
        from hexapod_vibration.cdr import decode_strut_cdr

        try:
            values, index, _ = decode_strut_cdr(data)
        except InvalidStrutMessage:
            return
        if index is None:
            return
        window = index // LEVEL_WINDOW_SAMPLES
        if window != self._current and self._window:
            self._close_window()
        self._current = window
        self._window[index] = float(self._z_row @ values)

    def _close_window(self) -> None:
        from hexapod_vibration.core.spectrum import to_db_re_g

        z = self._np.array(list(self._window.values()))
        if len(z) > LEVEL_WINDOW_SAMPLES // 2:
            rms = float(self._np.sqrt(self._np.mean((z - z.mean()) ** 2)))
            end_s = (self._current + 1) * LEVEL_WINDOW_SAMPLES / 1000.0
            self.samples.levels.append((end_s, float(to_db_re_g(rms))))
        self._window.clear()


def start_graph(params_file: Path, out: Path, composed: bool, has_notch: bool) -> list[Child]:
    """The driver and the controllers as processes that die with this one."""
    args = ["--ros-args", "--params-file", str(params_file)]
    names = ["pph_graph"] if composed else (
        (["notch_controller"] if has_notch else []) + ["pointing_controller", "pph_driver"])
    return [spawn_module(name, f"hexapod_vibration.nodes.{name}", args, out) for name in names]


def warnings_in_logs(children: list[Child]) -> dict[str, list[str]]:
    """Every [WARN]/[ERROR] line (and traceback) of each process's log."""
    found = {}
    for child in children:
        text = child.log.read_text(errors="replace") if child.log and child.log.exists() else ""
        lines = [ln for ln in text.splitlines()
                 if "[WARN]" in ln or "[ERROR]" in ln or "Traceback" in ln]
        found[child.name] = lines
    return found


def run(args: argparse.Namespace) -> int:
    """The soak itself; returns the exit code."""
    from hexapod_vibration.core.sim.scenario import load_scenario

    path = Path(args.scenario) if args.scenario.endswith((".yaml", ".yml")) \
        else scenario_path(args.scenario)
    scenario = load_scenario(path).with_timeline(args.duration, None)
    args.out.mkdir(parents=True, exist_ok=True)
    params_file = outputs.write_text(args.out / "params.yaml",
                                     params_file_text(scenario, "lockstep"))
    has_notch = bool(scenario.notch.tone_frequencies_hz)
    samples = Samples()
    children: list[Child] = []
    graph = None
    start_wall = time.monotonic()
    result: dict[str, Any] = {"scenario": scenario.name, "duration_s": args.duration,
                              "layout": "pph_graph" if args.composed else "processes"}
    try:
        children = start_graph(params_file, args.out, args.composed, has_notch)
        graph = GraphMonitor()
        AccelLevel(graph.node, samples)
        result.update(_drive(graph, children, samples, scenario, args, has_notch))
    except KeyboardInterrupt:
        result["interrupted"] = True
    finally:
        with cli.deferred():
            stop_all(children)
            if graph is not None:
                graph.close()
    result["wall_s"] = time.monotonic() - start_wall
    result["warnings"] = warnings_in_logs(children)
    result.update(_summarise(samples, result))
    _write(args.out, samples, result)
    _print(result)
    if result.get("interrupted"):
        return cli.interrupted_exit_code()
    return 0 if result["criteria"]["all_met"] else 1


def _drive(graph: GraphMonitor, children: list[Child], samples: Samples, scenario: Any,
           args: argparse.Namespace, has_notch: bool) -> dict[str, Any]:
    """Run until ``duration`` sim seconds; sample RSS; switch control on."""
    control_on = scenario.control_on_s if has_notch else None
    end_s = args.duration
    next_rss = 0.0
    last_print = 0.0
    while True:
        for child in children:
            if not child.alive():
                return {"died": f"{child.name} exited {child.process.returncode}: "
                                f"{child.tail(5)}"}
        graph.spin(0.2)
        sim = max(graph.sim_time_s, 0.0)
        now = time.monotonic()
        if now >= next_rss:
            next_rss = now + args.rss_every
            for proc in [*children, None]:
                pid = proc.pid if proc else os.getpid()
                mb = rss_mb(pid)
                if mb is not None:
                    samples.rss.setdefault(proc.name if proc else "soak", []).append(
                        (now, sim, mb))
        if control_on is not None and sim >= control_on:
            graph.set_parameter("notch_controller", "enabled", True)
            control_on = None
        if now - last_print > 30.0:
            last_print = now
            print(f"  soak: sim {sim:7.1f} / {end_s:g} s, loop {graph.driver.get('rate_hz', '?')} "
                  f"samples/s, notch {graph.notch.get('state', '-')}", flush=True)
        if sim >= end_s:
            return {"driver": dict(graph.driver), "notch": dict(graph.notch)}


def _summarise(samples: Samples, result: dict[str, Any]) -> dict[str, Any]:
    growth = {}
    for name, points in samples.rss.items():
        if not points:
            continue
        t0 = points[0][0]
        span = points[-1][0] - t0
        warm = max(WARMUP_MIN_S, WARMUP_FRACTION * span)
        kept = [p for p in points if p[0] - t0 >= warm] or points
        wall = growth_mb_per_h([(p[0], p[2]) for p in kept])
        sim = growth_mb_per_h([(p[1], p[2]) for p in kept])
        growth[name] = {"rss_mb_first": points[0][2], "rss_mb_last": points[-1][2],
                        "samples": len(points),
                        "mb_per_wall_hour_fit": wall[0], "mb_per_wall_hour_medians": wall[1],
                        "mb_per_sim_hour_fit": sim[0], "mb_per_sim_hour_medians": sim[1]}
    levels = [db for _, db in samples.levels]
    divergence: dict[str, Any] = {"windows": len(levels)}
    if levels:
        divergence.update(first_db=levels[0], last_db=levels[-1], best_db=min(levels),
                          last_above_best_db=levels[-1] - min(levels),
                          last_above_first_db=levels[-1] - levels[0])
    warnings = sum(len(v) for v in result.get("warnings", {}).values())
    driver = result.get("driver", {})
    worst = max((g["mb_per_sim_hour_fit"] for g in growth.values()), default=float("nan"))
    criteria = {
        "growth_under_5_mb_per_hour": bool(worst < GROWTH_LIMIT_MB_PER_H),
        "no_divergence": bool(levels) and divergence["last_above_best_db"]
        < DIVERGENCE_LIMIT_DB and divergence["last_above_first_db"] < 1.0,
        "no_warning": warnings == 0 and driver.get("timeouts", "0") == "0",
        "completed": "died" not in result and not result.get("interrupted"),
    }
    criteria["all_met"] = all(criteria.values())
    return {"memory": growth, "divergence": divergence, "warning_lines": warnings,
            "criteria": criteria}


def _write(out: Path, samples: Samples, result: dict[str, Any]) -> None:
    outputs.write_text(out / "soak.json", json.dumps(result, indent=2, default=str) + "\n")
    rows = ["process,wall_s,sim_s,rss_mb"]
    for name, points in samples.rss.items():
        t0 = points[0][0] if points else 0.0
        rows += [f"{name},{w - t0:.1f},{s:.3f},{mb:.2f}" for w, s, mb in points]
    outputs.write_text(out / "rss.csv", "\n".join(rows) + "\n")


def _print(result: dict[str, Any]) -> None:
    print(f"soak {result['scenario']}: {result['duration_s']:g} s simulated in "
          f"{result['wall_s']:.0f} s wall ({result['layout']})")
    for name, g in result["memory"].items():
        print(f"  {name:20s} RSS {g['rss_mb_first']:7.1f} -> {g['rss_mb_last']:7.1f} MB; growth "
              f"{g['mb_per_sim_hour_fit']:+.2f} MB/sim-hour (fit), "
              f"{g['mb_per_sim_hour_medians']:+.2f} (medians); "
              f"{g['mb_per_wall_hour_fit']:+.2f} MB/wall-hour")
    d = result["divergence"]
    if d.get("windows"):
        print(f"  z accel RMS: first {d['first_db']:.1f}, best {d['best_db']:.1f}, last "
              f"{d['last_db']:.1f} dB re 1 g ({d['windows']} windows of 10 s)")
    print(f"  warnings logged: {result['warning_lines']}; driver timeouts "
          f"{result.get('driver', {}).get('timeouts', '?')}")
    if "died" in result:
        print(f"  a process died: {result['died']}")
    print("  criteria: " + ", ".join(f"{k} {'yes' if v else 'NO'}"
                                     for k, v in result["criteria"].items()))


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``soak``."""
    cli.install_stop_handlers()
    args = build_parser().parse_args(argv)
    try:
        return run(args)
    except (ValueError, FileNotFoundError) as exc:
        return cli.fail("soak", exc)


if __name__ == "__main__":
    sys.exit(main())
