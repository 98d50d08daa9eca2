"""``summary.md`` of the benchmark: every number of ``results.json`` in Markdown tables."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hexapod_vibration.baseline.fxlms import DEFAULT_CONTROL_TAPS, DEFAULT_PATH_TAPS
from hexapod_vibration.bench.compiled_costs import EQUIVALENCE_SAMPLES
from hexapod_vibration.bench.costs import FXLMS_SAME_TONES
from hexapod_vibration.bench.node_budget import BudgetSetup
from hexapod_vibration.bench.table1 import EQUAL_ATTENUATION_TOL_DB
from hexapod_vibration.json_values import write_json
from hexapod_vibration.tools import outputs

FIFO_RECORDER_SETUP = BudgetSetup("processes", "realtime", priority=50).key
"""The CPU budget's set-up the realtime target through separate processes is read from."""


def _fmt(x: Any, digits: int = 2) -> str:
    if isinstance(x, float):
        return "NaN" if not np.isfinite(x) else f"{x:.{digits}f}"
    return str(x)


def _summary_costs(results: dict[str, Any]) -> list[str]:
    """Markdown lines: notch and FxLMS cost per sample in NumPy, ratios, multiply-adds."""
    lines = ["## Controller cost per sample, NumPy (us, median of "
             f"{results['timing']['repeat']} round-robin runs x {results['timing']['number']}"
             " steps)", "",
             "| struts x tones | notch decentralized | notch centralized |",
             "|---:|---:|---:|"]
    for t, v in results["notch_us_per_sample"].items():
        lines.append(f"| {t} | {_fmt(v)} | "
                     f"{_fmt(results['notch_centralized_us_per_sample'][t])} |")
    macs = results["multiply_adds_per_sample"]
    fx_l = results["scaling"]["fxlms_vs_path_taps"]
    fx_same = results[f"fxlms_{FXLMS_SAME_TONES}tones_us_per_sample"]
    cfg = results["fxlms_config"]
    lines += ["", f"| FxLMS 6x6, N={cfg['control_taps']} control taps, one reference per "
              f"tone | {cfg['reference_tones']} tones: us/sample | multiply-adds | "
              f"{FXLMS_SAME_TONES} tones: us/sample |", "|---|---:|---:|---:|"]
    for n, v in fx_l["us_per_sample"].items():
        lines.append(f"| L={n} secondary-path taps | {_fmt(v)} | "
                     f"{fx_l['multiply_adds_per_sample'][n]} | {_fmt(fx_same[n])} |")
    lines += [
        "",
        f"FxLMS (6x6, L={cfg['secondary_path_taps']}, N={cfg['control_taps']}, "
        f"**{cfg['reference_tones']} tones**, the configuration of the Table 1 run below) / "
        f"notch (6 ch, **8 tones**): **{_fmt(results['cost_ratio_fxlms_over_notch_6x8'])}x**"
        f" in time; both with 8 tones: {_fmt(results['cost_ratio_same_tones_6x8'])}x; both "
        f"with 2 tones: {_fmt(results['cost_ratio_fxlms_over_notch_6x2'])}x (6x8 ratio of "
        f"the fastest rounds: {_fmt(results['cost_ratio_fxlms_over_notch_6x8_of_minima'])}x)."
        f" Analytic multiply-adds: FxLMS {macs['fxlms_6x6_L64_N32_2tones']} (8 tones: "
        f"{macs[f'fxlms_6x6_L64_N32_{FXLMS_SAME_TONES}tones']}) vs notch 6x8 "
        f"{macs['notch_6x8']} ({_fmt(macs['ratio_fxlms_over_notch_6x8'], 1)}x) and 6x2 "
        f"{macs['notch_6x2']} ({_fmt(macs['ratio_fxlms_over_notch_6x2'], 1)}x).", "",
        f"NumPy floor: the {results['numpy_floor_calls']} array calls any NumPy notch step "
        f"needs (demodulate, scale, accumulate, output, rotate; 6x8 buffers, no checks) "
        f"take {_fmt(results['numpy_floor_us_per_sample'])} us, so no NumPy notch is "
        "cheaper, and against the costliest FxLMS timed here no NumPy comparison can "
        f"exceed {_fmt(results['numpy_cost_ratio_bound'], 1)}x.", ""]
    return lines + _summary_compiled(results)


def _summary_compiled(results: dict[str, Any]) -> list[str]:
    """Markdown lines: the compiled kernels' cost per sample and ratios."""
    cp = results.get("compiled", {})
    if "skipped" in cp or not cp:
        return [f"Compiled kernels: not measured ({cp.get('skipped', 'not run')}).", ""]
    same = cp[f"fxlms_{FXLMS_SAME_TONES}tones_us_per_sample"]
    notch = ", ".join(f"{k} {_fmt(v, 3)}" for k, v in cp["notch_us_per_sample"].items())
    lines = [f"## Controller cost per sample, compiled ({cp['engine']}; us, median of "
             f"{results['timing']['repeat']} rounds)", "",
             f"Notch (decentralized): {notch}.", "",
             f"| FxLMS 6x6, N={DEFAULT_CONTROL_TAPS} | 2 tones | {FXLMS_SAME_TONES} tones |",
             "|---|---:|---:|"]
    for n, v in cp["fxlms_us_per_sample"].items():
        lines.append(f"| L={n} | {_fmt(v, 3)} | {_fmt(same[n], 3)} |")
    diff = ", ".join(f"{k} {v:.1e}" for k, v in cp["max_relative_difference_vs_numpy"].items())
    return lines + [
        "",
        f"FxLMS (L={DEFAULT_PATH_TAPS}, 2 tones) / notch 6x8: "
        f"**{_fmt(cp['cost_ratio_fxlms_over_notch_6x8'], 1)}x** (fastest rounds "
        f"{_fmt(cp['cost_ratio_fxlms_over_notch_6x8_of_minima'], 1)}x); both with 8 tones: "
        f"{_fmt(cp['cost_ratio_same_tones_6x8'], 1)}x. The kernels are the same algorithms "
        "(baseline/compiled_kernels.py) stepping a block of errors per call, so the time is "
        "the arithmetic without the interpreter; their commands equal the NumPy "
        f"controllers' over {EQUIVALENCE_SAMPLES} samples within {diff} of the peak "
        f"(relative). Set-up and compilation: {_fmt(cp['setup_and_compile_s'], 1)} s.", ""]


def _summary_targets(results: dict[str, Any]) -> list[str]:
    """Markdown lines: the efficiency targets, met or not, and why."""
    tg = results["targets"]

    def verdict(met: bool) -> str:
        return "**met**" if met else "**not met**"

    compiled = tg["compiled_cost_ratio_6x8"]
    compiled_line = ("" if compiled is None else
                     f"Compiled, the same comparison is {_fmt(compiled, 1)}x: "
                     f"{verdict(tg['compiled_cost_ratio_met'])}. ")
    return [
        "## Issue targets", "",
        f"- Notch 6 struts x 8 tones under {tg['notch_6x8_target_us']:g} us per sample: "
        f"{verdict(tg['notch_6x8_met'])} ({_fmt(tg['notch_6x8_us'])} us).",
        f"- FxLMS at least {tg['cost_ratio_target']:g}x the notch 6x8 at equal attenuation, "
        f"both in vectorized NumPy: {verdict(tg['cost_ratio_met'])}: "
        f"{_fmt(tg['cost_ratio_6x8'])}x; the FxLMS timed here "
        + ("reaches" if tg["fxlms_equal_attenuation"] else "**does not reach**")
        + " the notch's attenuation on Table 1 (below). A NumPy step is a handful of array "
        f"calls whose fixed cost dominates at these sizes: the floor of any NumPy notch "
        f"step is {_fmt(tg['numpy_floor_us'])} us, which caps the NumPy ratio at "
        f"{_fmt(tg['numpy_cost_ratio_bound'], 1)}x even against the costliest FxLMS timed. "
        f"In arithmetic the FxLMS costs {_fmt(tg['multiply_add_ratio_6x8'], 1)}x the notch "
        f"6x8 (multiply-adds). {compiled_line}", ""]


def _summary_scaling(results: dict[str, Any]) -> list[str]:
    """Markdown lines: the scaling sweeps and their linear fits."""
    lines = ["## Scaling (us per sample)", "",
             "| sweep | points | slope | intercept | R^2 |", "|---|---|---:|---:|---:|"]
    sc = results["scaling"]
    for key, fit_key, unit in (("notch_vs_tones", "fit_us_per_tone", "us/tone"),
                               ("notch_vs_tones_large", "fit_us_per_tone", "us/tone"),
                               ("notch_vs_channels", "fit_us_per_channel", "us/channel"),
                               ("fxlms_vs_path_taps", "fit_us_per_tap", "us/tap")):
        fit = sc[key][fit_key]
        pts = ", ".join(f"{k}:{_fmt(v)}" for k, v in sc[key]["us_per_sample"].items())
        lines.append(f"| {key} | {pts} | {fit['slope']:.4f} {unit} | "
                     f"{_fmt(fit['intercept'])} | {fit['r2']:.3f} |")
    return lines + ["", f"Plant order: {sc['notch_plant_order']}.", ""]


def _summary_table1(results: dict[str, Any]) -> list[str]:
    """Markdown lines: both controllers on the Table 1 scenario."""
    t1 = results["table1"]
    lines = [f"## Table 1 scenario, core loop ({t1['duration_s']:g} s, control on at "
             f"{t1['control_on_s']:g} s, {t1['window_s']:g} s windows, z-axis, dB re 1 g)", "",
             "| controller | tone | uncontrolled | controlled | floor | attenuation | "
             "convergence (s) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name, run in t1["runs"].items():
        for f, e in run["tones"].items():
            att = (">= " if e["floor_limited"] else "") + _fmt(e["attenuation_db"], 1)
            conv = _fmt(e["convergence_s"]) if e["controlled"] else "-"
            ctl = (f"< {_fmt(e['noise_floor_db'], 1)}" if e["floor_limited"]
                   else _fmt(e["controlled_db"], 1))
            lines.append(f"| {name} | {f} Hz{'' if e['controlled'] else ' (not ctl)'} | "
                         f"{_fmt(e['uncontrolled_db'], 1)} | {ctl} | "
                         f"{_fmt(e['noise_floor_db'], 1)} | {att} | {conv} |")
    equal = "yes" if results["equal_attenuation"] else "no"
    lines += ["", f"notch: mu={t1['notch']['mu']:g} ({t1['notch']['adaptation']}); FxLMS: "
              f"mu={t1['fxlms']['mu']:g}, L={t1['fxlms']['path_taps']}, "
              f"N={t1['fxlms']['control_taps']}, {t1['fxlms']['reference']}. "
              "'<' and '>=': controlled level below the noise floor (the attenuation is a "
              "lower bound, set by the floor each controller leaves). Equal attenuation (both "
              f"floor-limited, or FxLMS within {EQUAL_ATTENUATION_TOL_DB:g} dB): {equal}. "
              "Convergence: control-on until the tone level over time (core.spectrum."
              "tone_level_over_time) first comes within 3 dB of its final level."]
    if "fxlms_model_relative_error" in t1:
        errs = ", ".join(f"{k} Hz {100 * v:.1f} %"
                         for k, v in t1["fxlms_model_relative_error"].items())
        lines.append(f"FxLMS FIR model vs tone identification (relative, Frobenius): {errs} "
                     "(the plant response has a slowly decaying tail; the attenuation does "
                     "not need a more accurate model).")
    return lines


def summary_markdown(results: dict[str, Any]) -> str:
    """A short Markdown report of every number and the machine."""
    m = results["machine_details"]
    lines = ["# hexapod_bench" + (" (quick)" if results.get("quick") else ""), "",
             f"Machine: {m['cpu_model']} ({m['processor']}), {m['cpu_count']} cores "
             f"({m['cpu_usable']} usable), load {m['load_average_1_5_15']}, {m['uname']}, "
             f"Python {m['python']}, numpy {m['numpy']}"
             + (f", plant kernels {m['plant_kernels']}." if "plant_kernels" in m else "."), ""]
    lines += _summary_costs(results)
    if "targets" in results:
        lines += _summary_targets(results)
    lines += _summary_scaling(results) + _summary_table1(results)
    if "sweep_throughput" in results:
        from hexapod_vibration.sweep.throughput import summary_lines
        lines += summary_lines(results)
    if "loops" in results:
        lines += _summary_ros(results)
    return "\n".join(lines) + "\n"


def _summary_ros(results: dict[str, Any]) -> list[str]:
    """Markdown lines: the ROS loop per layout and executor, and its targets."""
    from hexapod_vibration.bench.ros_bench import ros_summary_markdown  # rclpy only when measured

    rt, speedup = results["realtime"], results.get("lockstep_speedup") or float("nan")
    missed, p99 = rt.get("missed_fraction", float("nan")), rt.get("latency_ms_p99")
    p99 = float("nan") if p99 is None else p99

    def verdict(ok: bool) -> str:
        return "met" if ok else "**not met**"

    return ["", "## ROS loop (Table 1 settings, no recorder; driver-side measurements)", "",
            ros_summary_markdown(results), "",
            f"Headline (`realtime`, `lockstep_speedup` in results.json): {rt['executor']}.",
            f"- Realtime 1 kHz with under 0.1 % missed samples and p99 latency under 1 ms: "
            f"{verdict(_realtime_met(missed, p99))} ({100 * missed:.3f} % missed, p99 "
            f"{p99:.2f} ms over {_fmt(rt.get('duration_s'), 1)} s).",
            f"- Lockstep at least 3x faster than real time: {verdict(speedup >= 3.0)} "
            f"({_fmt(speedup)}x).",
            *_processes_headline(results.get("budget", {}), verdict),
            "Missed: the command of sample n not back when the driver advances past sample n; "
            "control on: from the driver's first report after the notch's identification was "
            "over (the canceller is off until then; its analysis, ~0.8 s of CPU, runs on a "
            "worker process in realtime; bench/late_window.py). Latency: publication of "
            "/pph/accel(n) to reception of /pph/notch_command(n) in the driver. Period: "
            "between publications of consecutive samples."]


def _realtime_met(missed_fraction: float, p99_ms: float) -> bool:
    """The realtime target: under 0.1 % of the samples missed, p99 latency under 1 ms."""
    return missed_fraction < 1e-3 and p99_ms < 1.0


def _processes_headline(budget: dict[str, Any], verdict) -> list[str]:
    """The realtime target through separate processes: the CPU budget's FIFO window."""
    window = budget.get(FIFO_RECORDER_SETUP, {})
    row = window.get("loop")
    if not row or row.get("missed_fraction") is None:
        return []
    missed, p99 = float(row["missed_fraction"]), float(row.get("latency_ms_p99", "nan"))
    return [f"- The same through separate processes (SCHED_FIFO 50, with the recorder, control "
            f"in force: the CPU budget's `{FIFO_RECORDER_SETUP}` window): "
            f"{verdict(_realtime_met(missed, p99))} ({100 * missed:.3f} % missed, p99 "
            f"{p99:.2f} ms over {_fmt(window.get('wall_s'), 1)} s)."]


def write_outputs(results: dict[str, Any], out_dir: Path) -> str:
    """Write ``results.json`` and ``summary.md`` into ``out_dir``; return the summary."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "results.json", results)
    summary = summary_markdown(results)
    outputs.write_text(out_dir / "summary.md", summary)
    return summary
