"""``experiment``: run one of the paper's experiments through the ROS graph and analyse it.

``experiment --scenario NAME --out DIR [--duration S] [--control-on S] [--lockstep|--realtime]
[--composed] [--storage mcap|sqlite3] [--twin]``

1. Writes ``DIR/params.yaml`` (a ROS 2 params file for the three nodes, from the scenario).
2. Starts the recorder (bag into ``DIR/bag``), the controllers and the driver as separate
   processes (``--composed``: the driver and controllers as one ``pph_graph`` process), on
   the caller's ROS_DOMAIN_ID, and waits until the graph is connected.
3. Lockstep: the driver holds (parameter ``hold_at_time_s``) before sample 0, at
   ``--control-on`` and at the end. At the control-on breakpoint the runner switches the
   notch controller on through its parameter service, so the switch lands on the same
   sample in every run and a run is reproducible. Realtime: the driver runs free at 1 kHz
   from its start breakpoint to the end one, and the runner switches control on when
   ``/clock`` passes ``--control-on``.
4. Waits at the end until the recorder wrote the last sample of every loop topic, stops
   every process with SIGINT (the recorder closes the bag), analyses the bag into
   ``DIR/report.json``, ``DIR/details.json`` and PNG plots, and prints the table.

Ctrl-C at any time stops all processes and leaves a readable bag. ``--demo`` runs the
paper's Tables 1 and 2 and Fig. 4 (``single_tone_harmonic``, ``close_tones``,
``plant_response``) into ``DIR/<scenario>``, prints the three tables with the paper's
reductions and writes ``DIR/summary.md``.

``--twin`` (lockstep, one scenario): after the run, the same scenario again with control
never on (same seeds, same identification) into ``DIR/twin`` (its bag, report.json and
details.json), then ``DIR/bag`` analysed against it (``analyze DIR/bag --twin
DIR/twin/bag``: report.json's ``twin`` section, and the figures).

The run record (scenario, tones, windows, planned identification, the paper's column) goes
into the bag's ``metadata.yaml`` ``custom_data``, so ``analyze DIR/bag`` gives exactly this
report. The runner releases the driver only when the recorder itself reports every loop
publisher matched (its ``/diagnostics``), so the bag has every sample from 0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexapod_vibration import cli
from hexapod_vibration.parameter_specs import STORAGES
from hexapod_vibration.paths import available_scenarios, scenario_path
from hexapod_vibration.ros.realtime import DEFAULT_REALTIME_PRIORITY, fifo_refusal
from hexapod_vibration.tools.experiment_run import (
    RunOptions,
    analyze_run,
    run_scenario,
    twin_scenario,
)
from hexapod_vibration.tools.experiment_setup import model_file_text, run_model_file
from hexapod_vibration.tools.graph_monitor import ExperimentError

if TYPE_CHECKING:       # imported where used: ``experiment --help`` stays cheap
    from hexapod_vibration.core.sim.scenario import Scenario

DEMO_SCENARIOS = ("single_tone_harmonic", "close_tones", "plant_response")


def build_parser() -> argparse.ArgumentParser:
    """Command-line interface of ``experiment`` (every value checked before any work)."""
    parser = cli.ArgumentParser(prog="experiment", description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", help=f"scenario name ({', '.join(available_scenarios())})"
                        " or a scenario YAML path")
    parser.add_argument("--out", type=cli.output_dir, required=True,
                        help="output directory (created; must not hold a bag already)")
    parser.add_argument("--duration", type=cli.duration_s, metavar="S",
                        help=f"override the duration (s, in (0, {cli.MAX_RUN_S:g}])")
    parser.add_argument("--control-on", type=cli.duration_s, metavar="S",
                        help="override the control-on time (s, in (0, duration])")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="deterministic, as fast as the graph allows (default)")
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="driver paced at 1 kHz wall clock")
    parser.add_argument("--composed", action="store_true",
                        help="driver and controllers as one process (pph_graph): same nodes "
                             "and topics, intra-process delivery, faster loop")
    parser.add_argument("--realtime-priority", type=cli.number(0, 98, integer=True), metavar="N",
                        default=None, help="run the driver and controllers under SCHED_FIFO at "
                        "priority N (1-98; needs CAP_SYS_NICE or an rtprio limit: refused "
                        "otherwise, with the reason); 0: the normal scheduler. Default: "
                        f"--realtime runs at {DEFAULT_REALTIME_PRIORITY} where the OS "
                        "permits it (said at start), else without; --lockstep at 0")
    parser.add_argument("--storage", choices=STORAGES, default="mcap",
                        help="rosbag2 storage of DIR/bag (default mcap, as Jazzy)")
    parser.add_argument("--no-plots", action="store_true",
                        help="skip the PNG figures (and spectra.csv): report.json, "
                             "details.json and the table only, as analyze --no-plots")
    parser.add_argument("--demo", action="store_true",
                        help="run the paper's Tables 1 and 2 and Fig. 4 into DIR/<scenario> "
                             "and write DIR/summary.md")
    parser.add_argument("--twin", action="store_true",
                        help="then run it again with control never on into DIR/twin and "
                             "compare the controlled window with the same samples of this "
                             "twin (report.json's 'twin' section; lockstep, one scenario)")
    parser.set_defaults(mode="lockstep")
    return parser


def _scenario(name: str, duration: float | None, control_on: float | None) -> Scenario:
    from hexapod_vibration.contract import SAMPLE_RATE_HZ
    from hexapod_vibration.core.sim.scenario import load_scenario
    from hexapod_vibration.core.sim.timeline import control_on_conflict

    path = Path(name) if name.endswith((".yaml", ".yml")) else scenario_path(name)
    if not path.is_file():
        raise FileNotFoundError(f"argument --scenario: {path} does not exist")
    scenario = load_scenario(path)
    model_file_text(scenario)                  # its model_overrides, checked before any work
    if duration is not None or control_on is not None:
        _check_timeline(scenario, duration, control_on)
    scenario = scenario.with_timeline(duration, control_on)
    conflict = control_on_conflict(scenario, SAMPLE_RATE_HZ)
    if conflict is not None:
        raise ValueError(f"{path}: {conflict}")
    return scenario


def _check_timeline(sc: Scenario, duration: float | None, control_on: float | None) -> None:
    duration = sc.duration_s if duration is None else duration
    control_on = sc.control_on_s if control_on is None else control_on
    if not 0.0 < control_on <= duration:
        raise ValueError(f"argument --control-on: must be in (0, duration = {duration:g}] s, "
                         f"got {control_on:g}")
    if duration < sc.window_s:
        raise ValueError(f"argument --duration: must be at least the scenario's window_s "
                         f"({sc.window_s:g} s), got {duration:g}")


def check_arguments(args: argparse.Namespace) -> list[Scenario]:
    """Every scenario of the command line, checked; ValueError/FileNotFoundError if not."""
    names = DEMO_SCENARIOS if args.demo else ([args.scenario] if args.scenario else [])
    if not names:
        raise ValueError("give --scenario NAME or --demo")
    if args.twin and args.demo:
        raise ValueError("argument --twin: not with --demo (give one --scenario)")
    if args.twin and args.mode != "lockstep":
        raise ValueError("argument --twin: needs --lockstep (a realtime run has no "
                         "sample-for-sample twin)")
    scenarios = [_scenario(n, args.duration, args.control_on) for n in names]
    for sc in scenarios:
        out = args.out / sc.name if args.demo else args.out
        for bag in [out / "bag", *([out / "twin" / "bag"] if args.twin else [])]:
            if bag.exists():
                raise ValueError(f"argument --out: {bag} exists: choose another --out or "
                                 "remove it")
        if args.twin and not 0.0 < sc.control_on_s < sc.duration_s:
            raise ValueError(f"argument --twin: control never goes on in {sc.name} "
                             f"(control_on_s {sc.control_on_s:g} s, duration "
                             f"{sc.duration_s:g} s): nothing to compare")
    return scenarios


def main(argv: list[str] | None = None) -> int:
    """Entry point: 0 success, 2 bad input, 1 the run failed, 130/143 on SIGINT/SIGTERM."""
    cli.install_stop_handlers()
    args = build_parser().parse_args(argv)
    try:
        scenarios = check_arguments(args)
    except (ValueError, FileNotFoundError) as exc:
        return cli.fail("experiment", exc)
    try:
        args.realtime_priority = realtime_priority(args.realtime_priority, args.mode)
        return _run_all(args, scenarios)
    except KeyboardInterrupt as exc:        # between two runs, or while printing
        return cli.interrupted_exit_code(exc)


def realtime_priority(asked: float | None, mode: str) -> int:
    """The loop nodes' SCHED_FIFO priority: as asked, else by mode (said in one line).

    Not asked: realtime runs at :data:`DEFAULT_REALTIME_PRIORITY` where the OS permits it
    and without otherwise (the reason printed; asked for, a priority the OS refuses stops
    the run instead); lockstep, whose pace no deadline sets, at 0.
    """
    if asked is not None:
        return int(asked)
    if mode != "realtime":
        return 0
    refusal = fifo_refusal(DEFAULT_REALTIME_PRIORITY)
    if refusal is None:
        print(f"experiment: realtime: the driver and controllers run under SCHED_FIFO "
              f"priority {DEFAULT_REALTIME_PRIORITY} (--realtime-priority 0: without)",
              flush=True)
        return DEFAULT_REALTIME_PRIORITY
    print(f"experiment: realtime without real-time priority: {refusal}; in separate "
          "processes several times more samples may be late (docs/performance.md)",
          flush=True)
    return 0


def _run_all(args: argparse.Namespace, scenarios: list[Scenario]) -> int:
    from hexapod_vibration.analysis.bag_files import BagError
    from hexapod_vibration.analysis.report_windows import WindowTooShort
    from hexapod_vibration.analysis.summary import write_summary

    tables, results = [], []
    for sc in scenarios:
        out = args.out / sc.name if args.demo else args.out
        print(f"experiment {sc.name}: {sc.description} ({args.mode}, {sc.duration_s:g} s, "
              f"control on at {sc.control_on_s:g} s) -> {out}", flush=True)
        runs = [(sc, out)]
        if args.twin:
            runs.append((twin_scenario(sc), out / "twin"))
        for k, (run_sc, run_out) in enumerate(runs):
            if k:
                print(f"experiment {sc.name}: its twin, control never on -> {run_out}",
                      flush=True)
            try:
                # With --twin the figures come with the comparison (below).
                result = run_scenario(RunOptions(
                    run_sc, run_out, args.mode, args.storage, composed=args.composed,
                    realtime_priority=int(args.realtime_priority)),
                    plots=not (args.twin or args.no_plots))
            except KeyboardInterrupt as exc:
                print(f"\nexperiment: interrupted; processes stopped, bag in "
                      f"{run_out / 'bag'}", file=sys.stderr, flush=True)
                return cli.interrupted_exit_code(exc)
            except (ExperimentError, BagError, WindowTooShort) as exc:
                print(f"experiment: {exc}", file=sys.stderr)
                return 2 if isinstance(exc, ExperimentError) and "exists" in str(exc) else 1
        if args.twin:
            try:
                result = analyze_run(out, run_model_file(out, sc), out / "twin" / "bag",
                                     plots=not args.no_plots)
            except KeyboardInterrupt as exc:
                print(f"\nexperiment: interrupted; bags in {out / 'bag'} and "
                      f"{out / 'twin' / 'bag'}", file=sys.stderr, flush=True)
                return cli.interrupted_exit_code(exc)
            except (BagError, ValueError) as exc:
                print(f"experiment: {' '.join(str(exc).split())}", file=sys.stderr)
                return 1
        results.append(result)
        tables.append(scenario_table(result))
        print(tables[-1], flush=True)
    if args.demo:
        print("\nThe paper's Tables 1 and 2 and Fig. 4 on the simulated hexapod:\n")
        print("\n\n".join(tables))
        summary = write_summary(args.out / "summary.md", results, args.out)
        print(f"\nwrote {summary}")
    return _control_exit_code(results)


NOT_ENGAGED = frozenset({"refused", "never_engaged"})
"""Outcomes of a run whose control never acted (``analysis.control_outcome``)."""


def _control_exit_code(results: list[Any]) -> int:
    """1 if a scenario asked for control that never engaged (said on stderr), else 0."""
    failed = [r.report for r in results
              if r.report.get("control", {}).get("outcome") in NOT_ENGAGED]
    for report in failed:
        control = report["control"]
        print(f"experiment: {report['scenario']}: control never engaged "
              f"({control['outcome']}: {control['reason'] or 'no reason given'})",
              file=sys.stderr)
    return 1 if failed else 0


def scenario_table(result: Any) -> str:
    """The printed table of one scenario: tones (with the paper's column) or harmonics."""
    from hexapod_vibration.analysis.report_tables import (
        format_following,
        format_harmonics,
        format_table,
    )

    if result.harmonics is not None and not any(
            r["controlled"] for r in result.report["tones"]):
        return format_harmonics(result.harmonics, result.report["scenario"])
    from hexapod_vibration.analysis.twin import format_twin

    parts = [format_table(result.report, result.paper_reduction_db),
             format_following(result.report), format_twin(result.report)]
    return "\n".join(p for p in parts if p)


if __name__ == "__main__":
    sys.exit(main())
