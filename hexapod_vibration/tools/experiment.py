"""``experiment``: run one of the paper's experiments through the ROS graph and analyse it.

``experiment --scenario NAME --out DIR [--duration S] [--control-on S] [--lockstep|--realtime]
[--composed] [--storage mcap|sqlite3]``

1. Writes ``DIR/params.yaml`` (a ROS 2 params file for the three nodes, from the scenario).
2. Starts the recorder (bag into ``DIR/bag``), the controllers and the driver as separate
   processes (``--composed``: the driver and controllers as one ``pph_graph`` process), on
   the caller's ROS_DOMAIN_ID, and waits until the graph is connected.
3. Lockstep: the driver holds (parameter ``hold_at_time_s``) before sample 0, at
   ``--control-on`` and at the end. At the control-on breakpoint the runner switches the
   notch controller on through its parameter service, so the switch lands on the same
   sample in every run and a run is reproducible. Realtime: the driver runs free at 1 kHz
   and the runner switches control on when ``/clock`` passes ``--control-on``.
4. Stops every process with SIGINT (the recorder closes the bag), analyses the bag into
   ``DIR/report.json``, ``DIR/details.json`` and PNG plots, and prints the table.

Ctrl-C at any time stops all processes and leaves a readable bag. ``--demo`` runs the two
tables of the paper (``single_tone_harmonic``, ``close_tones``) into ``DIR/<scenario>`` and
prints them side by side with the paper's reductions.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexapod_vibration import cli
from hexapod_vibration.contract import DRIVER_STATUS, NOTCH_STATUS
from hexapod_vibration.parameter_specs import STORAGES
from hexapod_vibration.paths import available_scenarios, config_path, scenario_path
from hexapod_vibration.tools import outputs
from hexapod_vibration.tools.processes import Child, spawn_module, stop_all

if TYPE_CHECKING:       # imported where used: ``experiment --help`` stays cheap
    from hexapod_vibration.core.sim.scenario import Scenario

PAPER_REDUCTION_DB = {
    "single_tone_harmonic": {40.0: 66.4, 80.0: 40.2, 120.0: -10.0},
    "close_tones": {37.0: -8.0, 38.0: -11.6, 39.0: 60.1, 40.0: 59.1, 41.0: -1.0, 42.0: -4.8},
}
DEMO_SCENARIOS = ("single_tone_harmonic", "close_tones")
STOP_TIMEOUT_S = 15.0


class ExperimentError(RuntimeError):
    """The experiment could not run (a process died, the graph never came up, ...)."""


# ---------------------------------------------------------------------------- parameters
def node_parameters(scenario: Scenario, mode: str) -> dict[str, dict[str, Any]]:
    """The ROS params file content (``{node: {"ros__parameters": {...}}}``) of a scenario."""
    sh, notch = scenario.shaker, scenario.notch
    has_notch = bool(notch.tone_frequencies_hz)
    driver: dict[str, Any] = {
        "clock_mode": mode, "nonlinear": scenario.nonlinear, "seed": scenario.seed,
        "shaker_frequencies_hz": list(sh.frequencies_hz) or [40.0],
        "shaker_amplitudes_n": list(sh.amplitudes_n) or [0.0],
        "shaker_drift_hz": sh.drift_hz, "shaker_drift_period_s": sh.drift_period_s,
        "shaker_noise_rms_n": sh.noise_rms_n,
        "test_sine_frequency_hz": scenario.test_sine.frequency_hz or 40.0,
        "test_sine_amplitude_n": scenario.test_sine.amplitude_n,
        "lockstep_controllers": ["notch", "pointing"] if has_notch else ["pointing"],
    }
    if sh.phases_rad:
        driver["shaker_phases_rad"] = list(sh.phases_rad)
    pose = [math.degrees(a) for a in scenario.target_pose[3:]]
    params = {
        "pph_driver": driver,
        "pointing_controller": {
            "target_translation_m": [float(x) for x in scenario.target_pose[:3]],
            "target_tilt_x_deg": pose[0],
            "target_tilt_y_deg": pose[1],
            "target_twist_deg": pose[2],
        },
    }
    if has_notch:
        params["notch_controller"] = {
            "tone_frequencies_hz": list(notch.tone_frequencies_hz), "mu": notch.mu,
            "adaptation": notch.adaptation, "enabled": False,
            "identify_delay_s": scenario.identify_at_s,
        }
    return {node: {"ros__parameters": values} for node, values in params.items()}


PARAMS_FILE_HEADER = """\
# Parameters of the nodes of this experiment ({scenario}, {mode}), written by `experiment`.
# The same run with the launch file (from this folder):
#   ros2 launch hexapod_vibration pph.launch.py params_file:=$PWD/params.yaml \\
#       clock_mode:={mode} record:=true bag_path:=$PWD/bag_launch
#   ros2 param set /notch_controller enabled true     # at sim time {control_on_s:g} s
# The runner did the same, plus breakpoints it gave on the driver's command line
# (lockstep: -p hold_at_time_s:=0.0, moved to {control_on_s:g} s, then {duration_s:g} s),
# so that its control-on switch landed on sample {control_on_sample} exactly.
"""


def params_file_text(scenario: Scenario, mode: str) -> str:
    """``params.yaml``: the nodes' parameters of a scenario, reusable with the launch file."""
    import yaml

    header = PARAMS_FILE_HEADER.format(
        scenario=scenario.name, mode=mode, control_on_s=scenario.control_on_s,
        duration_s=scenario.duration_s, control_on_sample=round(scenario.control_on_s * 1e3))
    return header + yaml.safe_dump(node_parameters(scenario, mode), sort_keys=False)


# ---------------------------------------------------------------------------- processes
def start_child(name: str, module: str, ros_args: list[str], log_dir: Path) -> Child:
    """``python -m module --ros-args ...`` (output in ``log_dir/name.log``), dying with us."""
    return spawn_module(name, module, ["--ros-args", *ros_args], log_dir)


def stop_children(children: list[Child]) -> None:
    """SIGINT each process in turn (the given order), wait; SIGKILL its group if stuck."""
    with cli.deferred():
        stop_all(children, STOP_TIMEOUT_S)


# ---------------------------------------------------------------------------- supervisor
class Supervisor:
    """In-process rclpy node: watches /clock and /diagnostics, sets parameters."""

    def __init__(self, watch_clock: bool = True) -> None:
        """Create the node on the caller's domain.

        ``watch_clock=False``: no ``/clock`` subscription (a benchmark that must not add a
        1 kHz subscriber to the loop it measures); ``sim_time_s`` then follows the
        driver's ``sample`` on /diagnostics (once per simulated second).
        """
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.parameter_client import AsyncParameterClient
        from rclpy.signals import SignalHandlerOptions
        from rosgraph_msgs.msg import Clock

        from hexapod_vibration.ros.qos import CLOCK_QOS, DIAGNOSTICS_QOS

        self._rclpy = rclpy
        # No rclpy signal handlers: they would shut this context down from another thread
        # in the middle of a call (tracebacks); cli.StopSignal unwinds instead.
        rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("experiment")
        self.sim_time_s = -1.0
        self.driver: dict[str, str] = {}
        self.notch: dict[str, str] = {}
        self._watch_clock = watch_clock
        if watch_clock:
            self.node.create_subscription(Clock, "/clock", self._on_clock, CLOCK_QOS)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag,
                                      DIAGNOSTICS_QOS)
        self.clients = {name: AsyncParameterClient(self.node, name)
                        for name in ("pph_driver", "notch_controller", "pointing_controller")}

    def _on_clock(self, msg: Any) -> None:
        self.sim_time_s = msg.clock.sec + msg.clock.nanosec * 1e-9

    def _on_diag(self, msg: Any) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name == DRIVER_STATUS:
                self.driver = values
                if not self._watch_clock:
                    self.sim_time_s = max(self.sim_time_s, int(values.get("sample", 0)) / 1e3)
            elif status.name == NOTCH_STATUS:
                self.notch = values

    def spin(self, seconds: float) -> None:
        """Process callbacks for ``seconds`` of wall time."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._rclpy.spin_once(self.node, timeout_sec=max(0.0, min(0.05, end -
                                                                      time.monotonic())))

    def graph_ready(self, with_notch: bool) -> bool:
        """Recorder, controllers and driver are all discovered on the loop topics."""
        n = self.node
        needed = [n.count_subscribers("/pph/accel") >= (2 if with_notch else 1),
                  n.count_subscribers("/pph/eddy") >= 2,
                  n.count_publishers("/pph/accel") >= 1,
                  n.count_publishers("/pph/pointing_command") >= 1]
        if with_notch:
            needed.append(n.count_publishers("/pph/notch_command") >= 1)
        return all(needed)

    def set_parameter(self, node: str, name: str, value: Any, timeout_s: float = 10.0) -> None:
        """Set a parameter through the node's parameter service; raise if rejected."""
        from rclpy.parameter import Parameter

        client = self.clients[node]
        if not client.wait_for_services(timeout_sec=timeout_s):
            raise ExperimentError(f"/{node} parameter services not available")
        future = client.set_parameters([Parameter(name, value=value)])
        self._rclpy.spin_until_future_complete(self.node, future, timeout_sec=timeout_s)
        if not future.done():
            raise ExperimentError(f"/{node}: no answer setting {name}")
        result = future.result().results[0]
        if not result.successful:
            raise ExperimentError(f"/{node} rejected {name}={value!r}: {result.reason}")

    def held_at(self, sample: int) -> bool:
        """True once the driver reported being held before ``sample``."""
        return self.driver.get("held") == "true" and int(self.driver.get("sample", -1)) == sample

    def close(self) -> None:
        """Destroy the node and shut rclpy down."""
        self.node.destroy_node()
        self._rclpy.try_shutdown()


# ---------------------------------------------------------------------------- the run
@dataclass
class RunOptions:
    """What to run and where."""

    scenario: Scenario
    out: Path
    mode: str = "lockstep"
    storage: str = "mcap"
    wall_timeout_s: float = 0.0
    composed: bool = False
    """Driver and controllers in one process (``pph_graph``) instead of three."""


class ExperimentRun:
    """One scenario through the ROS graph: start, drive the timeline, stop."""

    def __init__(self, options: RunOptions) -> None:
        """Prepare the output directory (refuses to overwrite an existing bag)."""
        self.o = options
        self.bag = options.out / "bag"
        if self.bag.exists():
            raise ExperimentError(f"{self.bag} exists: choose another --out or remove it")
        options.out.mkdir(parents=True, exist_ok=True)
        self.params_file = options.out / "params.yaml"
        outputs.write_text(self.params_file, params_file_text(options.scenario, options.mode))
        self.children: list[Child] = []
        self.sup: Supervisor | None = None
        sc = options.scenario
        self.has_notch = bool(sc.notch.tone_frequencies_hz)
        self.n_on = int(round(sc.control_on_s * 1000)) if sc.control_on_s < sc.duration_s else -1
        self.n_end = sc.samples
        default_timeout = 60.0 + 10.0 * sc.duration_s
        self.deadline = time.monotonic() + (options.wall_timeout_s or default_timeout)
        self._last_progress = 0.0

    def start(self) -> None:
        """Recorder first, then the controllers, the driver last."""
        logs = self.o.out
        common = ["--params-file", str(self.params_file)]
        self.children.append(start_child("pph_recorder", "hexapod_vibration.nodes.recorder", [
            "-p", f"bag_path:={self.bag}", "-p", f"storage:={self.o.storage}"], logs))
        if self.o.composed:
            self.children.append(start_child("pph_graph", "hexapod_vibration.nodes.pph_graph",
                                             common + self._breakpoint("pph_driver:"), logs))
        else:
            if self.has_notch:
                self.children.append(start_child(
                    "notch_controller", "hexapod_vibration.nodes.notch_controller", common, logs))
            self.children.append(start_child(
                "pointing_controller", "hexapod_vibration.nodes.pointing_controller", common, logs))
            self.children.append(start_child("pph_driver", "hexapod_vibration.nodes.pph_driver",
                                             common + self._breakpoint(), logs))
        self.sup = Supervisor()

    def _breakpoint(self, prefix: str = "") -> list[str]:
        """Lockstep: the driver starts held before sample 0 (after the params file: wins)."""
        return ["-p", f"{prefix}hold_at_time_s:=0.0"] if self.o.mode == "lockstep" else []

    def _check(self) -> None:
        for child in self.children:
            if not child.alive():
                raise ExperimentError(f"{child.name} exited with {child.process.returncode}:\n"
                                      f"{child.tail()}")
        if time.monotonic() > self.deadline:
            raise ExperimentError("wall-clock timeout: the loop is not advancing")

    def _wait(self, predicate, what: str) -> None:
        while not predicate():
            self._check()
            self.sup.spin(0.05)
            self._progress(what)

    def _progress(self, what: str) -> None:
        now = time.monotonic()
        if now - self._last_progress < 2.0:
            return
        self._last_progress = now
        rate = self.sup.driver.get("rate_hz", "?")
        state = self.sup.notch.get("state", "-")
        print(f"  [{self.o.scenario.name}] sim {max(self.sup.sim_time_s, 0.0):6.2f} / "
              f"{self.o.scenario.duration_s:.1f} s  loop {rate} samples/s  notch {state}  "
              f"({what})", flush=True)

    def run(self) -> None:
        """Drive the timeline (see the module docstring)."""
        self.start()
        self._wait(lambda: self.sup.graph_ready(self.has_notch), "waiting for the graph")
        self.sup.spin(1.0)       # discovery is not matching: let the readers settle
        if self.o.mode == "lockstep":
            self._run_lockstep()
        else:
            self._run_realtime()
        self.sup.spin(1.0)       # let the recorder drain its queues

    def _run_lockstep(self) -> None:
        sc = self.o.scenario
        self._wait(lambda: self.sup.held_at(0), "driver at its start breakpoint")
        if self.n_on > 0:
            self.sup.set_parameter("pph_driver", "hold_at_time_s", sc.control_on_s)
            self._wait(lambda: self.sup.held_at(self.n_on), "running with control off")
            self.sup.set_parameter("notch_controller", "enabled", True)
            print(f"  [{sc.name}] control on at {sc.control_on_s:.3f} s (sample {self.n_on})",
                  flush=True)
        self.sup.set_parameter("pph_driver", "hold_at_time_s", sc.duration_s)
        self._wait(lambda: self.sup.held_at(self.n_end), "running")

    def _run_realtime(self) -> None:
        sc = self.o.scenario
        if self.n_on > 0:
            self._wait(lambda: self.sup.sim_time_s >= sc.control_on_s, "running, control off")
            self.sup.set_parameter("notch_controller", "enabled", True)
            print(f"  [{sc.name}] control on at sim {self.sup.sim_time_s:.3f} s", flush=True)
        self._wait(lambda: self.sup.sim_time_s >= sc.duration_s, "running")

    def stop(self) -> None:
        """Stop every process (recorder last, so the bag holds everything) and rclpy."""
        order = sorted(self.children, key=lambda c: c.name == "pph_recorder")
        stop_children(order)
        if self.sup is not None:
            self.sup.close()
            self.sup = None


def run_scenario(options: RunOptions) -> dict[str, Any]:
    """Run, stop, analyse; return the report. Ctrl-C stops cleanly and re-raises."""
    run = ExperimentRun(options)
    try:
        run.run()
    finally:
        run.stop()
    from hexapod_vibration.analysis.report import analyze_bag
    from hexapod_vibration.core.model.config import load_model_config

    sc = options.scenario
    model = load_model_config(config_path("pph_model.yaml"))
    with outputs.staged(options.out) as staging:     # every file complete, or none
        result = analyze_bag(run.bag, staging, model, list(sc.report_tones_hz) or None,
                             sc.name, sc.window_s, harmonics_of_hz=sc.report_harmonics_of_hz)
    return result.report


# ---------------------------------------------------------------------------- CLI
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
    parser.add_argument("--storage", choices=STORAGES, default="mcap",
                        help="rosbag2 storage of DIR/bag (default mcap, as Jazzy)")
    parser.add_argument("--demo", action="store_true",
                        help="run the paper's Tables 1 and 2 into DIR/<scenario>")
    parser.set_defaults(mode="lockstep")
    return parser


def _scenario(name: str, duration: float | None, control_on: float | None) -> Scenario:
    from hexapod_vibration.core.sim.scenario import load_scenario

    path = Path(name) if name.endswith((".yaml", ".yml")) else scenario_path(name)
    if not path.is_file():
        raise FileNotFoundError(f"argument --scenario: {path} does not exist")
    scenario = load_scenario(path)
    if duration is not None or control_on is not None:
        _check_timeline(scenario, duration, control_on)
    return scenario.with_timeline(duration, control_on)


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
    scenarios = [_scenario(n, args.duration, args.control_on) for n in names]
    for sc in scenarios:
        bag = (args.out / sc.name if args.demo else args.out) / "bag"
        if bag.exists():
            raise ValueError(f"argument --out: {bag} exists: choose another --out or remove it")
    return scenarios


def side_by_side(left: str, right: str, gap: int = 4) -> str:
    """Two text blocks next to each other."""
    a, b = left.splitlines(), right.splitlines()
    width = max(map(len, a)) + gap
    rows = max(len(a), len(b))
    a += [""] * (rows - len(a))
    b += [""] * (rows - len(b))
    return "\n".join(f"{x:<{width}}{y}" for x, y in zip(a, b, strict=True))


def main(argv: list[str] | None = None) -> int:
    """Entry point: 0 success, 2 bad input, 1 the run failed, 130/143 on SIGINT/SIGTERM."""
    cli.install_stop_handlers()
    args = build_parser().parse_args(argv)
    try:
        scenarios = check_arguments(args)
    except (ValueError, FileNotFoundError) as exc:
        return cli.fail("experiment", exc)
    try:
        return _run_all(args, scenarios)
    except KeyboardInterrupt as exc:        # between two runs, or while printing
        return cli.interrupted_exit_code(exc)


def _run_all(args: argparse.Namespace, scenarios: list[Scenario]) -> int:
    from hexapod_vibration.analysis.bag_io import BagError
    from hexapod_vibration.analysis.report import format_table

    tables = []
    for sc in scenarios:
        out = args.out / sc.name if args.demo else args.out
        print(f"experiment {sc.name}: {sc.description} ({args.mode}, {sc.duration_s:g} s, "
              f"control on at {sc.control_on_s:g} s) -> {out}", flush=True)
        try:
            report = run_scenario(RunOptions(sc, out, args.mode, args.storage,
                                             composed=args.composed))
        except KeyboardInterrupt as exc:
            print(f"\nexperiment: interrupted; processes stopped, bag in {out / 'bag'}",
                  file=sys.stderr, flush=True)
            return cli.interrupted_exit_code(exc)
        except (ExperimentError, BagError) as exc:
            print(f"experiment: {exc}", file=sys.stderr)
            return 2 if isinstance(exc, ExperimentError) and "exists" in str(exc) else 1
        tables.append(format_table(report, PAPER_REDUCTION_DB.get(sc.name)))
        print(tables[-1], flush=True)
    if len(tables) == 2:
        print("\nPaper Tables 1 and 2 on the simulated hexapod (dB re 1 g):")
        print(side_by_side(*tables))
    return 0


if __name__ == "__main__":
    sys.exit(main())
