"""One scenario through the ROS graph: start the processes, drive the timeline, stop, analyse.

The recorder first, then the controllers and the driver (each a process that dies with this
one), which holds before sample 0 until the recorder matched every publisher; lockstep: it
holds at breakpoints (control-on, the end too) and the runner switches control on at its
breakpoint, so a run is reproducible; realtime: control goes on when the sim time (the
driver's reports, paced by the wall clock) passes control-on, and the clock stops at the end
breakpoint. At the end (both modes) the runner waits until the recorder wrote the last sample
of every loop topic, then stops the processes. A run fails when a process dies or nothing
moves for ``STALL_TIMEOUT_S``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexapod_vibration import cli
from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    NOTCH_FREQUENCIES_TOPIC,
    NOTCH_SENSITIVITY_TOPIC,
    REFERENCE_FREQUENCY_TOPIC,
)
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.dds_transport import realtime_transport_env
from hexapod_vibration.tools import outputs
from hexapod_vibration.tools.experiment_setup import (
    model_file_text,
    params_file_text,
    rotor_parameters,
    run_model_file,
    run_record,
)
from hexapod_vibration.tools.graph_monitor import ExperimentError, GraphMonitor
from hexapod_vibration.tools.processes import Child, spawn_module, stop_all
from hexapod_vibration.tools.progress import Progress

if TYPE_CHECKING:       # imported where used: ``experiment --help`` stays cheap
    from hexapod_vibration.core.sim.scenario import Scenario

STOP_TIMEOUT_S = 15.0
STALL_TIMEOUT_S = 120.0
"""The run fails when neither sim time nor the recorder's loop topics move for this long
(s, wall)."""
RECORDER_DRAIN = "recorder writing the last samples"
WRITERS_MATCHING = "every publisher matching its subscribers"
DRIVER_TOPICS = ("/pph/accel", "/pph/eddy", "/pph/actuator_force", "/clock",
                 DISTURBANCE_FREQUENCIES_TOPIC)
NOTCH_TOPICS = ("/pph/notch_command", "/pph/notch_weights", NOTCH_FREQUENCIES_TOPIC,
                NOTCH_SENSITIVITY_TOPIC)
POINTING_TOPICS = ("/pph/pointing_command",)


def start_child(name: str, module: str, ros_args: list[str], log_dir: Path,
                env: dict[str, str] | None = None) -> Child:
    """``python -m module --ros-args ...`` (output in ``log_dir/name.log``), dying with us."""
    return spawn_module(name, module, ["--ros-args", *ros_args], log_dir, env)


def stop_children(children: list[Child]) -> None:
    """SIGINT each process in turn (the given order), wait; SIGKILL its group if stuck."""
    with cli.deferred():
        stop_all(children, STOP_TIMEOUT_S)


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
    realtime_priority: int = 0
    """SCHED_FIFO priority of the loop's processes (0: the normal scheduler)."""


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
            options.scenario, options.mode, str(self.model_file or ""),
            options.realtime_priority))
        self.record = run_record(options.scenario, options.mode)
        self.children: list[Child] = []
        self.graph: GraphMonitor | None = None
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
        """Recorder first, then the controllers and the driver.

        The driver holds before sample 0 until the recorder matched every publisher (see
        :meth:`run`), so nothing is lost and its start-up, ~2 s of imports, overlaps theirs.
        """
        logs = self.o.out
        common = ["--params-file", str(self.params_file)]
        env = None
        if not self.lockstep:
            env, note = realtime_transport_env(os.environ)
            if note:
                print(f"experiment: realtime: {note}", flush=True)
        self.children.append(start_child("pph_recorder", "hexapod_vibration.nodes.recorder", [
            *common, "-p", f"bag_path:={self.bag}", "-p", f"storage:={self.o.storage}"], logs,
            env))
        # The breakpoints and the progress come from the driver's status (in realtime paced
        # by the wall clock): a 1 kHz /clock reader here would cost the runner three quarters
        # of its CPU (rclpy's executor waking for it) and the driver a reader to serve.
        self.graph = GraphMonitor(paced=not self.lockstep)
        if self.o.composed:
            self.children.append(start_child("pph_graph", "hexapod_vibration.nodes.pph_graph",
                                             common + self._breakpoint("pph_driver:"), logs,
                                             env))
            return
        if self.has_notch:
            self.children.append(start_child(
                "notch_controller", "hexapod_vibration.nodes.notch_controller", common, logs,
                env))
        self.children.append(start_child(
            "pointing_controller", "hexapod_vibration.nodes.pointing_controller", common, logs,
            env))
        self.children.append(start_child("pph_driver", "hexapod_vibration.nodes.pph_driver",
                                         common + self._breakpoint(), logs, env))

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
        """The driver starts held before sample 0 (after the params file: wins).

        Realtime too: its clock starts when the recorder matched every publisher, so the
        bag has every sample from 0 (without it, the first ~3 s went unrecorded).
        """
        return ["-p", f"{prefix}hold_at_time_s:=0.0"]

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
        graph = self.graph
        topics = self.recorded_topics()
        key = (graph.sim_time_s, what, tuple(graph.recorder.get(f"{t} messages") for t in topics),
               graph.driver.get("sample"))
        if key != self._progress_key:
            self._progress_key, self._progress_at = key, now
        elif now - self._progress_at > STALL_TIMEOUT_S:
            behind = ", ".join(f"{t} {graph.recorder.get(f'{t} last sample', '-1')}"
                               for t in graph.recorder_behind(self.loop_topics(), self.n_end))
            if what == RECORDER_DRAIN and behind:
                detail = (f" (last sample recorded, of {self.n_end - 1}: {behind}; the rest "
                          "never reached the recorder)")
            elif what == WRITERS_MATCHING:
                detail = (" (publishers short of the subscriptions on: "
                          f"{', '.join(graph.writers_unmatched(self.matched_topics()))})")
            else:
                detail = ""
            raise ExperimentError(f"the loop is not advancing: nothing changed for "
                                  f"{STALL_TIMEOUT_S:g} s while {what}{detail}")

    def _wait(self, predicate, what: str) -> None:
        while not predicate():
            self._check(what)
            self.graph.spin(0.05)
            self._progress(what)

    def _progress(self, what: str) -> None:
        graph = self.graph
        self.progress.update(max(graph.sim_time_s, 0.0), graph.driver.get("rate_hz"),
                             graph.notch.get("state", "-"), what)

    def say(self, text: str) -> None:
        """A line of its own (ends the progress line first)."""
        self.progress.clear()
        print(text, flush=True)

    def run(self) -> None:
        """Drive the timeline (see the module docstring)."""
        self.start()
        self._wait(lambda: self.graph.graph_ready(self.has_notch), "waiting for the graph")
        # Discovery is not matching: the recorder itself must report every publisher matched
        # (before the driver leaves its start breakpoint, so the bag has sample 0).
        self._wait(lambda: not self.graph.recorder_unmatched(self.recorded_topics()),
                   "recorder matching every publisher")
        # and every publisher matching the recorder: see writers_unmatched
        self._wait(lambda: not self.graph.writers_unmatched(self.matched_topics()),
                   WRITERS_MATCHING)
        self._wait(lambda: self.graph.held_at(0), "driver at its start breakpoint")
        if self.lockstep:
            self._run_lockstep()
        else:
            self._run_realtime()
        # The loop is held at its last sample: wait until the recorder wrote the last sample
        # of every loop topic (it may lag the loop by seconds, a starved recorder on a busy
        # machine in realtime too; stopping the driver then would lose them).
        loop = self.loop_topics()
        self._wait(lambda: not self.graph.recorder_behind(loop, self.n_end), RECORDER_DRAIN)

    def _run_lockstep(self) -> None:
        sc = self.o.scenario
        if self.n_on > 0:
            self.graph.set_parameter("pph_driver", "hold_at_time_s", sc.control_on_s)
            self._wait(lambda: self.graph.held_at(self.n_on), "running with control off")
            self.graph.set_parameter("notch_controller", "enabled", True)
            self.say(f"  [{sc.name}] control on at {sc.control_on_s:.3f} s (sample {self.n_on})")
        self.graph.set_parameter("pph_driver", "hold_at_time_s", sc.duration_s)
        self._wait(lambda: self.graph.held_at(self.n_end), "running")

    def _run_realtime(self) -> None:
        """Release the start breakpoint to the end one: the clock runs to the run's end."""
        sc = self.o.scenario
        self.graph.set_parameter("pph_driver", "hold_at_time_s", sc.duration_s)
        if self.n_on > 0:
            self._wait(lambda: self.graph.sim_time_s >= sc.control_on_s, "running, control off")
            self.graph.set_parameter("notch_controller", "enabled", True)
            self.say(f"  [{sc.name}] control on at sim {self.graph.sim_time_s:.3f} s")
        self._wait(lambda: self.graph.held_at(self.n_end), "running")

    def stop(self) -> None:
        """Stop every process and rclpy: the driver first, the recorder last.

        The driver first: a driver still running while its controllers stop (a run
        interrupted before its end breakpoint, in realtime) counts their missing answers as
        late commands; the recorder last, so the bag holds everything.
        """
        self.progress.clear()
        order = sorted(self.children,
                       key=lambda c: (c.name != "pph_driver", c.name == "pph_recorder"))
        stop_children(order)
        if self.graph is not None:
            self.graph.close()
            self.graph = None


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
