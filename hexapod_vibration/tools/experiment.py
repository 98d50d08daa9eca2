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
   and the runner switches control on when ``/clock`` passes ``--control-on``.
4. Stops every process with SIGINT (the recorder closes the bag), analyses the bag into
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
import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexapod_vibration import cli
from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    DRIVER_STATUS,
    NOTCH_FREQUENCIES_TOPIC,
    NOTCH_SENSITIVITY_TOPIC,
    NOTCH_STATUS,
    POINTING_STATUS,
    REFERENCE_FREQUENCY_TOPIC,
)
from hexapod_vibration.parameter_specs import STORAGES
from hexapod_vibration.paths import available_scenarios, config_path, scenario_path
from hexapod_vibration.tools import outputs
from hexapod_vibration.tools.processes import Child, spawn_module, stop_all

if TYPE_CHECKING:       # imported where used: ``experiment --help`` stays cheap
    from hexapod_vibration.analysis.run_record import RunRecord
    from hexapod_vibration.core.sim.scenario import Scenario

PAPER_REDUCTION_DB = {
    "single_tone_harmonic": {40.0: 66.4, 80.0: 40.2, 120.0: -10.0},
    "close_tones": {37.0: -8.0, 38.0: -11.6, 39.0: 60.1, 40.0: 59.1, 41.0: -1.0, 42.0: -4.8},
}
DEMO_SCENARIOS = ("single_tone_harmonic", "close_tones", "plant_response")
STOP_TIMEOUT_S = 15.0
STALL_TIMEOUT_S = 120.0
"""The run fails when neither sim time nor the recorder's loop topics move for this long
(s, wall)."""
RECORDER_DRAIN = "recorder writing the last samples"
WRITERS_MATCHING = "every publisher matching its subscribers"
EXPERIMENT_LOCKSTEP_TIMEOUT_S = 10.0
"""The driver's ``lockstep_timeout_s`` in an experiment (s, wall): the parameter's maximum."""
DRIVER_TOPICS = ("/pph/accel", "/pph/eddy", "/pph/actuator_force", "/clock",
                 DISTURBANCE_FREQUENCIES_TOPIC)
NOTCH_TOPICS = ("/pph/notch_command", "/pph/notch_weights", NOTCH_FREQUENCIES_TOPIC,
                NOTCH_SENSITIVITY_TOPIC)
POINTING_TOPICS = ("/pph/pointing_command",)


class ExperimentError(RuntimeError):
    """The experiment could not run (a process died, the graph never came up, ...)."""


# ---------------------------------------------------------------------------- parameters
def node_parameters(scenario: Scenario, mode: str, model_file: str = ""
                    ) -> dict[str, dict[str, Any]]:
    """The ROS params file content (``{node: {"ros__parameters": {...}}}``) of a scenario.

    ``model_file``: the model YAML of a scenario with ``model_overrides`` (see
    :func:`model_file_text`), given to the nodes that simulate or use the physical model.
    """
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
        # A recorded run waits for a late answer rather than apply a zero command in its
        # place (a loaded machine; the runner itself stops the run if a process dies).
        "lockstep_timeout_s": EXPERIMENT_LOCKSTEP_TIMEOUT_S,
    }
    if sh.phases_rad:
        driver["shaker_phases_rad"] = list(sh.phases_rad)
    driver.update(rotor_parameters(scenario))
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
    if model_file:
        for node in ("pph_driver", "pointing_controller"):
            params[node]["model_file"] = model_file
    if has_notch:
        params["notch_controller"] = {
            **{k: list(v) if isinstance(v, tuple) else v for k, v in notch.settings.items()},
            "tone_frequencies_hz": list(notch.tone_frequencies_hz), "mu": notch.mu,
            "adaptation": notch.adaptation, "enabled": False,
            "identify_delay_s": scenario.identify_at_s,
        }
    return {node: {"ros__parameters": values} for node, values in params.items()}


def rotor_parameters(scenario: Scenario) -> dict[str, Any]:
    """The driver's ``rotor_*`` parameters of the scenario's ``rotor:`` (none without one)."""
    rotor = scenario.rotor
    if not rotor.orders:
        return {}
    return {"rotor_orders": list(rotor.orders), "rotor_amplitudes_n": list(rotor.amplitudes_n),
            "rotor_reference_speed_hz": float(rotor.reference_speed_hz),
            "rotor_profile_time_s": list(rotor.profile_time_s),
            "rotor_profile_speed_hz": list(rotor.profile_speed_hz),
            "rotor_tachometer": bool(rotor.tachometer)}


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


def model_file_text(scenario: Scenario) -> str:
    """The scenario's physical model as a model YAML: the packaged one with its overrides.

    Empty when the scenario has no ``model_overrides`` (the nodes use the packaged model).
    Raises ``ValueError`` on an override the model does not have or an invalid value.
    """
    import yaml

    from hexapod_vibration.core.model.config import merged_model_mapping, model_config_from_dict

    if not scenario.model_overrides:
        return ""
    source = config_path("pph_model.yaml")
    with open(source, encoding="utf-8") as stream:
        packaged = yaml.safe_load(stream)
    merged = merged_model_mapping(packaged, scenario.model_overrides, scenario.name)
    model_config_from_dict(merged, source=scenario.name)        # every value checked
    header = (f"# The physical model of scenario {scenario.name}, written by `experiment`:\n"
              f"# the packaged pph_model.yaml with the scenario's model_overrides\n"
              f"# {scenario.model_overrides}\n")
    return header + yaml.safe_dump(merged, sort_keys=False)


def run_model_file(out: Path, scenario: Scenario) -> Path | None:
    """Where a run in ``out`` keeps its model YAML (:func:`model_file_text`); None: packaged."""
    return (out / "model.yaml").resolve() if scenario.model_overrides else None


def params_file_text(scenario: Scenario, mode: str, model_file: str = "") -> str:
    """``params.yaml``: the nodes' parameters of a scenario, reusable with the launch file.

    The recorder's section carries the run record (what ``analyze`` needs to report the run
    as planned), so a launch-recorded bag is reported the same way.
    """
    import yaml

    header = PARAMS_FILE_HEADER.format(
        scenario=scenario.name, mode=mode, control_on_s=scenario.control_on_s,
        duration_s=scenario.duration_s, control_on_sample=round(scenario.control_on_s * 1e3))
    params = node_parameters(scenario, mode, model_file)
    params["pph_recorder"] = {"ros__parameters": {
        "run_record": run_record(scenario, mode).to_json()}}
    return header + yaml.safe_dump(params, sort_keys=False)


def run_record(scenario: Scenario, mode: str) -> RunRecord:
    """What the bag must say about this run so that ``analyze`` reports it as planned."""
    from hexapod_vibration.analysis.run_record import RunRecord
    from hexapod_vibration.core.control.adaptation import ToneResponseIdentifier

    notch = [float(f) for f in scenario.notch.tone_frequencies_hz]
    on = int(round(scenario.control_on_s * 1000)) if scenario.control_on_s < scenario.duration_s \
        else -1
    ident = (int(round(ToneResponseIdentifier(6, notch, 1000.0).duration_s * 1000))
             if notch else 0)
    return RunRecord(
        scenario=scenario.name,
        report_tones_hz=[float(f) for f in scenario.report_tones_hz] or notch,
        notch_tones_hz=notch, window_s=float(scenario.window_s), samples=scenario.samples,
        control_on_sample=on,
        identify_at_sample=int(round(scenario.identify_at_s * 1000)) if notch else -1,
        identification_samples=ident,
        harmonics_of_hz=float(scenario.report_harmonics_of_hz),
        paper_reduction_db={f"{f:g}": v for f, v in
                            PAPER_REDUCTION_DB.get(scenario.name, {}).items()},
        mode=mode)


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
        self.pointing: dict[str, str] = {}
        self.recorder: dict[str, str] = {}
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
            elif status.name == POINTING_STATUS:
                self.pointing = values
            elif status.name.startswith("pph_recorder"):
                self.recorder = values

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

    def recorder_behind(self, topics: list[str], samples: int) -> list[str]:
        """Topics of which the recorder reports fewer than ``samples`` messages written."""
        return [t for t in topics if int(self.recorder.get(f"{t} messages", "0")) < samples]

    def recorder_unmatched(self, topics: list[str]) -> list[str]:
        """Topics on which the recorder itself reports no matched publisher yet."""
        return [t for t in topics if int(self.recorder.get(f"{t} publishers", "0")) < 1]

    def writers_unmatched(self, topics: list[str]) -> list[str]:
        """Topics whose publisher has not matched every subscription the graph shows yet.

        The publishers' side (:mod:`hexapod_vibration.ros.matching`): a subscription that
        matched its publisher may not be matched by it yet, and loses what it sends.
        """
        from hexapod_vibration.ros.matching import unmatched_topics

        return unmatched_topics((self.driver, self.notch, self.pointing), topics,
                                self.node.count_subscribers)

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
    """Longest wall time of the whole run (s; 0 = none: only a stalled loop fails it)."""
    composed: bool = False
    """Driver and controllers in one process (``pph_graph``) instead of three."""


class Progress:
    """Progress of a run: one updating line with an ETA on a terminal, plain lines otherwise.

    The ETA extrapolates the sim time's rate over the run so far (wall s per sim s).
    """

    TTY_PERIOD_S = 0.5
    PLAIN_PERIOD_S = 5.0

    def __init__(self, name: str, duration_s: float, stream: Any = None) -> None:
        """Report on ``stream`` (default stdout) for a run of ``duration_s`` sim seconds."""
        self.name, self.duration_s = name, duration_s
        self.stream = stream or sys.stdout
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._start: tuple[float, float] | None = None
        self._last = -math.inf
        self._shown = False

    def line(self, sim_s: float, rate_hz: str | None, state: str, what: str, now: float
             ) -> str:
        """The progress text at wall time ``now`` (monotonic s)."""
        if self._start is None or sim_s < self._start[1]:
            self._start = (now, sim_s)
        wall0, sim0 = self._start
        speed = (sim_s - sim0) / (now - wall0) if now > wall0 and sim_s > sim0 else 0.0
        eta = (f"ETA {_duration_text((self.duration_s - sim_s) / speed)}" if speed > 0
               else "ETA -")
        try:
            rate = f"{float(rate_hz):.0f} samples/s"
        except (TypeError, ValueError):
            rate = "- samples/s"
        return (f"  [{self.name}] sim {sim_s:5.1f} / {self.duration_s:g} s "
                f"({100 * min(sim_s / self.duration_s, 1.0):3.0f} %), {eta}, loop {rate}, "
                f"notch {state}: {what}")

    def update(self, sim_s: float, rate_hz: str | None, state: str, what: str) -> None:
        """Show the progress (rate-limited)."""
        now = time.monotonic()
        text = self.line(sim_s, rate_hz, state, what, now)
        if now - self._last < (self.TTY_PERIOD_S if self.tty else self.PLAIN_PERIOD_S):
            return
        self._last = now
        if self.tty:
            self.stream.write(f"\r{text}\x1b[K")
            self._shown = True
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def clear(self) -> None:
        """End the updating line (terminal only) so that other output starts clean."""
        if self._shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._shown = False


def _duration_text(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    return f"{seconds // 60}:{seconds % 60:02d}"


class ExperimentRun:
    """One scenario through the ROS graph: start, drive the timeline, stop."""

    def __init__(self, options: RunOptions) -> None:
        """Prepare the output directory (refuses to overwrite an existing bag)."""
        self.o = options
        self.bag = options.out / "bag"
        if self.bag.exists():
            raise ExperimentError(f"{self.bag} exists: choose another --out or remove it")
        options.out.mkdir(parents=True, exist_ok=True)
        self.model_file = run_model_file(options.out, options.scenario)
        if self.model_file is not None:
            outputs.write_text(self.model_file, model_file_text(options.scenario))
        self.params_file = options.out / "params.yaml"
        outputs.write_text(self.params_file, params_file_text(
            options.scenario, options.mode, str(self.model_file or "")))
        self.record = run_record(options.scenario, options.mode)
        self.children: list[Child] = []
        self.sup: Supervisor | None = None
        sc = options.scenario
        self.has_notch = bool(sc.notch.tone_frequencies_hz)
        self.n_on = int(round(sc.control_on_s * 1000)) if sc.control_on_s < sc.duration_s else -1
        self.n_end = sc.samples
        now = time.monotonic()
        self.deadline = now + options.wall_timeout_s if options.wall_timeout_s > 0 else math.inf
        self._progress_key: tuple = ()
        self._progress_at = now
        self.progress = Progress(sc.name, sc.duration_s)

    @property
    def lockstep(self) -> bool:
        """True for a lockstep run (the driver holds at breakpoints), False for realtime."""
        return self.o.mode == "lockstep"

    def start(self) -> None:
        """Recorder first, then the controllers; the driver when the recorder matched them.

        Lockstep: the driver starts with the controllers (it holds before sample 0 until
        the recorder matched every publisher, so nothing is lost and its start-up, ~2 s
        of imports, overlaps theirs).
        """
        logs = self.o.out
        common = ["--params-file", str(self.params_file)]
        self.children.append(start_child("pph_recorder", "hexapod_vibration.nodes.recorder", [
            *common, "-p", f"bag_path:={self.bag}", "-p", f"storage:={self.o.storage}"], logs))
        # Lockstep: the breakpoints and the progress come from the driver's status; a 1 kHz
        # /clock reader here only cost the runner (75 % of its CPU was rclpy's executor
        # waking for it) and the driver a reader to serve.
        self.sup = Supervisor(watch_clock=not self.lockstep)
        if self.o.composed:
            self.children.append(start_child("pph_graph", "hexapod_vibration.nodes.pph_graph",
                                             common + self._breakpoint("pph_driver:"), logs))
            return
        if self.has_notch:
            self.children.append(start_child(
                "notch_controller", "hexapod_vibration.nodes.notch_controller", common, logs))
        self.children.append(start_child(
            "pointing_controller", "hexapod_vibration.nodes.pointing_controller", common, logs))
        if not self.lockstep:
            controllers = [*POINTING_TOPICS, *(NOTCH_TOPICS if self.has_notch else ())]
            self._wait(lambda: not self.sup.recorder_unmatched(controllers),
                       "recorder matching the controllers")
        self.children.append(start_child("pph_driver", "hexapod_vibration.nodes.pph_driver",
                                         common + self._breakpoint(), logs))

    def recorded_topics(self) -> list[str]:
        """Every topic whose publishers the recorder must match before sample 0."""
        tachometer = (REFERENCE_FREQUENCY_TOPIC,) if rotor_parameters(
            self.o.scenario).get("rotor_tachometer") else ()
        return [*DRIVER_TOPICS, *tachometer, *POINTING_TOPICS,
                *(NOTCH_TOPICS if self.has_notch else ())]

    def matched_topics(self) -> list[str]:
        """The recorded topics whose publishers must match every subscriber before sample 0.

        (The notch's latched sensitivity reaches a late subscriber anyway.)
        """
        return [t for t in self.recorded_topics() if t != NOTCH_SENSITIVITY_TOPIC]

    def loop_topics(self) -> list[str]:
        """The per-sample topics the bag must hold every sample of."""
        from hexapod_vibration.analysis.bag_format import STRUT_TOPICS

        return [t for t in STRUT_TOPICS if t != "/pph/notch_command" or self.has_notch]

    def _breakpoint(self, prefix: str = "") -> list[str]:
        """Lockstep: the driver starts held before sample 0 (after the params file: wins)."""
        return ["-p", f"{prefix}hold_at_time_s:=0.0"] if self.lockstep else []

    def _check(self, what: str) -> None:
        for child in self.children:
            if not child.alive():
                raise ExperimentError(f"{child.name} exited with {child.process.returncode}:\n"
                                      f"{child.tail()}")
        now = time.monotonic()
        if now > self.deadline:
            raise ExperimentError(f"wall-clock timeout ({self.o.wall_timeout_s:g} s) while "
                                  f"{what}")
        # Progress: sim time, what is awaited, or the recorder's counts changed. A loaded
        # machine only slows them down; nothing changing for STALL_TIMEOUT_S is a hang.
        # (Only the loop topics' counts: /diagnostics and /parameter_events are recorded
        # too and grow every second whatever the loop does.)
        sup = self.sup
        topics = self.recorded_topics()
        key = (sup.sim_time_s, what, tuple(sup.recorder.get(f"{t} messages") for t in topics),
               sup.driver.get("sample"))
        if key != self._progress_key:
            self._progress_key, self._progress_at = key, now
        elif now - self._progress_at > STALL_TIMEOUT_S:
            behind = ", ".join(f"{t} {sup.recorder.get(f'{t} messages', '0')}"
                               for t in sup.recorder_behind(self.loop_topics(), self.n_end))
            if what == RECORDER_DRAIN and behind:
                detail = (f" (recorded of {self.n_end} samples: {behind}; the rest never "
                          "reached the recorder)")
            elif what == WRITERS_MATCHING:
                detail = (" (publishers short of the subscriptions on: "
                          f"{', '.join(sup.writers_unmatched(self.matched_topics()))})")
            else:
                detail = ""
            raise ExperimentError(f"the loop is not advancing: nothing changed for "
                                  f"{STALL_TIMEOUT_S:g} s while {what}{detail}")

    def _wait(self, predicate, what: str) -> None:
        while not predicate():
            self._check(what)
            self.sup.spin(0.05)
            self._progress(what)

    def _progress(self, what: str) -> None:
        sup = self.sup
        self.progress.update(max(sup.sim_time_s, 0.0), sup.driver.get("rate_hz"),
                             sup.notch.get("state", "-"), what)

    def say(self, text: str) -> None:
        """A line of its own (ends the progress line first)."""
        self.progress.clear()
        print(text, flush=True)

    def run(self) -> None:
        """Drive the timeline (see the module docstring)."""
        self.start()
        self._wait(lambda: self.sup.graph_ready(self.has_notch), "waiting for the graph")
        # Discovery is not matching: the recorder itself must report every publisher matched
        # (lockstep: before the driver leaves its start breakpoint, so the bag has sample 0).
        self._wait(lambda: not self.sup.recorder_unmatched(self.recorded_topics()),
                   "recorder matching every publisher")
        if self.lockstep:      # and every publisher matching the recorder: see writers_unmatched
            self._wait(lambda: not self.sup.writers_unmatched(self.matched_topics()),
                       WRITERS_MATCHING)
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
            self.say(f"  [{sc.name}] control on at {sc.control_on_s:.3f} s (sample {self.n_on})")
        self.sup.set_parameter("pph_driver", "hold_at_time_s", sc.duration_s)
        self._wait(lambda: self.sup.held_at(self.n_end), "running")
        # The loop is held at its last sample: wait until the recorder wrote every sample
        # (it may lag a fast lockstep loop by seconds; stopping it then would lose them).
        loop = self.loop_topics()
        self._wait(lambda: not self.sup.recorder_behind(loop, self.n_end), RECORDER_DRAIN)

    def _run_realtime(self) -> None:
        sc = self.o.scenario
        if self.n_on > 0:
            self._wait(lambda: self.sup.sim_time_s >= sc.control_on_s, "running, control off")
            self.sup.set_parameter("notch_controller", "enabled", True)
            self.say(f"  [{sc.name}] control on at sim {self.sup.sim_time_s:.3f} s")
        self._wait(lambda: self.sup.sim_time_s >= sc.duration_s, "running")

    def stop(self) -> None:
        """Stop every process (recorder last, so the bag holds everything) and rclpy."""
        self.progress.clear()
        order = sorted(self.children, key=lambda c: c.name == "pph_recorder")
        stop_children(order)
        if self.sup is not None:
            self.sup.close()
            self.sup = None


def run_scenario(options: RunOptions, plots: bool = True) -> Any:
    """Run, stop, analyse; return the Analysis. Ctrl-C stops cleanly and re-raises.

    The analysis is ``analyze DIR/bag``'s: everything comes from the run record in the bag
    (``plots=False``: report.json and details.json only).
    """
    run = ExperimentRun(options)
    try:
        run.run()
    finally:
        run.stop()
    return analyze_run(options.out, run.model_file, plots=plots)


def analyze_run(out: Path, model_file: Path | None, twin_bag: Path | None = None,
                plots: bool = True) -> Any:
    """``analyze OUT/bag [--twin TWIN_BAG] --out OUT`` with the run's model (None: packaged)."""
    from hexapod_vibration.analysis.bag_analysis import analyze_bag
    from hexapod_vibration.core.model.config import load_model_config

    model = load_model_config(model_file or config_path("pph_model.yaml"))
    with outputs.staged(out) as staging:     # every file complete, or none
        return analyze_bag(out / "bag", staging, model, twin_bag=twin_bag, plots=plots)


def twin_scenario(scenario: Scenario) -> Scenario:
    """The same scenario with control never on (the runner then never sets ``enabled``)."""
    return dataclasses.replace(scenario, control_on_s=scenario.duration_s)


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
                        help="run the paper's Tables 1 and 2 and Fig. 4 into DIR/<scenario> "
                             "and write DIR/summary.md")
    parser.add_argument("--twin", action="store_true",
                        help="then run it again with control never on into DIR/twin and "
                             "compare the controlled window with the same samples of this "
                             "twin (report.json's 'twin' section; lockstep, one scenario)")
    parser.set_defaults(mode="lockstep")
    return parser


def _scenario(name: str, duration: float | None, control_on: float | None) -> Scenario:
    from hexapod_vibration.core.sim.scenario import load_scenario

    path = Path(name) if name.endswith((".yaml", ".yml")) else scenario_path(name)
    if not path.is_file():
        raise FileNotFoundError(f"argument --scenario: {path} does not exist")
    scenario = load_scenario(path)
    model_file_text(scenario)                  # its model_overrides, checked before any work
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
        return _run_all(args, scenarios)
    except KeyboardInterrupt as exc:        # between two runs, or while printing
        return cli.interrupted_exit_code(exc)


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
                result = run_scenario(RunOptions(run_sc, run_out, args.mode, args.storage,
                                                 composed=args.composed), plots=not args.twin)
            except KeyboardInterrupt as exc:
                print(f"\nexperiment: interrupted; processes stopped, bag in "
                      f"{run_out / 'bag'}", file=sys.stderr, flush=True)
                return cli.interrupted_exit_code(exc)
            except (ExperimentError, BagError, WindowTooShort) as exc:
                print(f"experiment: {exc}", file=sys.stderr)
                return 2 if isinstance(exc, ExperimentError) and "exists" in str(exc) else 1
        if args.twin:
            try:
                result = analyze_run(out, run_model_file(out, sc), out / "twin" / "bag")
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
    return 0


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
