"""``hexapod_bench``: the controllers' cost per sample and their suppression, on this machine.

Makes the paper's efficiency claim measurable: the Adaptive Notch Canceller's cost per
sample against the classic model-based multiple-error filtered-x LMS
(:mod:`hexapod_vibration.baseline.fxlms`, one reference per tone), its growth with the number
of tones and channels, its independence of the plant order, and both controllers'
attenuation and convergence on the paper's Table 1 scenario (core closed loop, no ROS).
The FxLMS is timed in the configuration whose attenuation the same run checks against the
notch's (``equal_attenuation``), and ``targets`` states whether the efficiency targets
(notch 6x8 under 20 us per sample; FxLMS / notch 6x8 at least 10x) are met.

Usage: ``hexapod_bench --out DIR [--quick] [--skip-ros] [--skip-sweep]``
(:mod:`hexapod_vibration.bench.cli`). Writes ``DIR/results.json`` and ``DIR/summary.md``
and prints the summary. Without ``--skip-ros`` the ROS loop benchmark
(``hexapod_vibration.bench.ros_bench.ros_loop_benchmark``) adds its keys (``realtime``,
``lockstep_speedup``); without ``--skip-sweep`` the sweep throughput
(``hexapod_vibration.sweep.throughput``, needs dask) adds ``sweep_throughput``.

The parts: :mod:`~hexapod_vibration.bench.timing` (how a step is timed),
:mod:`~hexapod_vibration.bench.controllers` (what is timed),
:mod:`~hexapod_vibration.bench.costs` and :mod:`~hexapod_vibration.bench.compiled_costs`,
:mod:`~hexapod_vibration.bench.table1`, :mod:`~hexapod_vibration.bench.machine` and
:mod:`~hexapod_vibration.bench.summary` (``summary.md``).
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

from hexapod_vibration.bench.compiled_costs import measure_compiled_costs
from hexapod_vibration.bench.costs import RATIO_NOTCH_TONES, measure_costs
from hexapod_vibration.bench.machine import machine_info, machine_summary
from hexapod_vibration.bench.summary import write_outputs
from hexapod_vibration.bench.table1 import measure_table1
from hexapod_vibration.bench.timing import FULL_TIMING, QUICK_TIMING

NOTCH_TARGET_US = 20.0
"""Target: the notch, 6 struts x 8 tones, under this many us per sample."""
COST_RATIO_TARGET = 10.0
"""Target: the FxLMS costs at least this many times the notch 6x8, at equal attenuation."""


def efficiency_targets(results: dict[str, Any]) -> dict[str, Any]:
    """The efficiency targets against this run's numbers (booleans and values).

    ``cost_ratio_met`` is the targets' measurement (both controllers in vectorized NumPy);
    ``compiled_cost_ratio_met`` the same comparison of the compiled kernels (arithmetic).
    """
    notch_us = results["notch_us_per_sample"][f"6x{RATIO_NOTCH_TONES}"]
    ratio = results["cost_ratio_fxlms_over_notch_6x8"]
    equal = bool(results["equal_attenuation"])
    compiled = results.get("compiled", {}).get("cost_ratio_fxlms_over_notch_6x8")
    return {
        "notch_6x8_us": notch_us, "notch_6x8_target_us": NOTCH_TARGET_US,
        "notch_6x8_met": bool(notch_us < NOTCH_TARGET_US),
        "cost_ratio_6x8": ratio, "cost_ratio_target": COST_RATIO_TARGET,
        "fxlms_equal_attenuation": equal,
        "cost_ratio_met": bool(ratio >= COST_RATIO_TARGET and equal),
        "numpy_floor_us": results["numpy_floor_us_per_sample"],
        "numpy_cost_ratio_bound": results["numpy_cost_ratio_bound"],
        "compiled_cost_ratio_6x8": compiled,
        "compiled_cost_ratio_met": bool(compiled is not None
                                        and compiled >= COST_RATIO_TARGET and equal),
        "multiply_add_ratio_6x8": results["multiply_adds_per_sample"][
            "ratio_fxlms_over_notch_6x8"],
    }


def run_core_benchmarks(quick: bool) -> dict[str, Any]:
    """Everything but the ROS loop: machine, costs, scaling, Table 1 on the core loop."""
    timing = QUICK_TIMING if quick else FULL_TIMING
    details = machine_info()
    results: dict[str, Any] = {"quick": quick, "machine": machine_summary(details),
                               "machine_details": details,
                               "timing": dataclasses.asdict(timing)}
    results.update(measure_costs(timing, quick))
    results.update(measure_compiled_costs(timing))
    results.update(measure_table1(quick))
    results["targets"] = efficiency_targets(results)
    return results


def run(args: Any) -> int:
    """Run the benchmarks of checked arguments (``bench/cli.py``); returns the exit code."""
    ros_loop_benchmark = None
    if not args.skip_ros:
        try:
            from hexapod_vibration.bench.ros_bench import ros_loop_benchmark
        except ModuleNotFoundError as exc:
            if exc.name != "hexapod_vibration.bench.ros_bench":
                raise
            print("hexapod_bench: error: the ROS loop benchmark is not available; run with "
                  "--skip-ros", file=sys.stderr)
            return 2
    results = run_core_benchmarks(args.quick)
    if not args.skip_sweep:
        from hexapod_vibration.sweep.throughput import sweep_throughput
        results.update(sweep_throughput(args.quick))
    if ros_loop_benchmark is not None:
        write_outputs(results, args.out)          # keep the core numbers if ROS fails
        results.update(ros_loop_benchmark(args.out, args.quick))
    summary = write_outputs(results, args.out)
    sys.stdout.write(summary)
    return 0
