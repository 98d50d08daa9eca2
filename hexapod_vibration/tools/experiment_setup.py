"""What an experiment writes before it starts: the nodes' params file, the model, the run record.

``params.yaml`` is a ROS 2 params file for the three nodes (and the recorder's run record),
reusable with the launch file; a scenario with ``model_overrides`` gets its own model YAML.
No ROS import.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hexapod_vibration.paths import config_path

if TYPE_CHECKING:       # imported where used: ``experiment --help`` stays cheap
    from hexapod_vibration.analysis.run_record import RunRecord
    from hexapod_vibration.core.sim.scenario import Scenario

PAPER_REDUCTION_DB = {
    "single_tone_harmonic": {40.0: 66.4, 80.0: 40.2, 120.0: -10.0},
    "close_tones": {37.0: -8.0, 38.0: -11.6, 39.0: 60.1, 40.0: 59.1, 41.0: -1.0, 42.0: -4.8},
}

EXPERIMENT_LOCKSTEP_TIMEOUT_S = 10.0
"""The driver's ``lockstep_timeout_s`` in an experiment (s, wall): the parameter's maximum."""


REALTIME_COMMAND_DELAY_SAMPLES = 2
"""The ``command_delay_samples`` of every loop node in a realtime experiment: a controller
has three periods (3 ms) to answer, and one behind its loop answers the newest three
samples queued. Through separate processes on the project machine (docs/performance.md):
one period missed a few % of the notch's answers, each held answer corrupting the
identification's input; against two periods (delay 1), interleaved, three runs each, the
late commands fell from 3 141-3 961 to 1 636-1 806 of 41 100 and the identification's
confidence rose from 0.943-0.967 to 0.976-0.984. The notch controller adds it to its
``loop_delay_samples`` (the stability bound's delay)."""


def node_parameters(scenario: Scenario, mode: str, model_file: str = "",
                    realtime_priority: int = 0) -> dict[str, dict[str, Any]]:
    """The ROS params file content (``{node: {"ros__parameters": {...}}}``) of a scenario.

    ``model_file``: the model YAML of a scenario with ``model_overrides`` (see
    :func:`model_file_text`), given to the nodes that simulate or use the physical model.
    ``realtime_priority``: SCHED_FIFO priority of the loop's nodes (0: not set).
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
    if mode == "realtime":
        _pipeline(params, REALTIME_COMMAND_DELAY_SAMPLES)
        if has_notch:           # the identification's analysis off the loop's thread
            params["notch_controller"]["identification_analysis"] = "process"
    if realtime_priority:
        for values in params.values():
            values["realtime_priority"] = int(realtime_priority)
    return {node: {"ros__parameters": values} for node, values in params.items()}


def _pipeline(params: dict[str, dict[str, Any]], delay_samples: int) -> None:
    """Set every loop node's command delay (samples; the notch adds it to its loop delay)."""
    for node in ("pph_driver", "notch_controller", "pointing_controller"):
        if node in params:
            params[node]["command_delay_samples"] = delay_samples


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
# (-p hold_at_time_s:=0.0, moved to {control_on_s:g} s in lockstep, then {duration_s:g} s),
# so that the bag starts at sample 0, ends at the run's end and (lockstep) its control-on
# switch landed on sample {control_on_sample} exactly.
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


def params_file_text(scenario: Scenario, mode: str, model_file: str = "",
                     realtime_priority: int = 0) -> str:
    """``params.yaml``: the nodes' parameters of a scenario, reusable with the launch file.

    The recorder's section carries the run record (what ``analyze`` needs to report the run
    as planned), so a launch-recorded bag is reported the same way.
    """
    import yaml

    header = PARAMS_FILE_HEADER.format(
        scenario=scenario.name, mode=mode, control_on_s=scenario.control_on_s,
        duration_s=scenario.duration_s, control_on_sample=round(scenario.control_on_s * 1e3))
    params = node_parameters(scenario, mode, model_file, realtime_priority)
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
