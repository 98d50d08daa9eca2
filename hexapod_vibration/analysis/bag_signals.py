"""What the analysis needs from one bag, read in one streaming pass, sample-indexed.

The top plate's z acceleration per sample (recovered from the six accelerometers through
the Stewart Jacobian), the sample accounting of every topic, decimated eddy gaps and notch
weights, the notch's statuses, the recorded frequencies and sensitivity, the run record,
and when control went on; memory grows with nothing but 8 bytes per accelerometer sample.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexapod_vibration.analysis.bag_format import ACCEL_TOPIC, RUN_RECORD_KEY, STRUT_TOPICS
from hexapod_vibration.analysis.bag_reading import read_bag
from hexapod_vibration.analysis.run_record import RunRecord
from hexapod_vibration.analysis.strut_streams import Keep, StrutSeries
from hexapod_vibration.contract import DRIVER_STATUS, NOTCH_STATUS, SAMPLE_RATE_HZ, NotchState
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.geometry import CubicHexapodGeometry
from hexapod_vibration.core.model.sensors import EddySensorArray

FS = SAMPLE_RATE_HZ

POSE_BLOCK = 100
"""Pointing figure: the pose's mean and RMS deviation per block of 100 samples (0.1 s)."""
COMMAND_EVERY = 10
"""Notch-command timestamps kept (for a bag-timestamp latency estimate): every 10th."""
WEIGHTS_EVERY = 10
"""Notch weights kept for the convergence figure: every 10th message (10 Hz)."""


@dataclass
class BagSignals:
    """What the analysis needs from one bag, sample-indexed.

    ``series["/pph/accel"].values`` holds the top plate's z acceleration (m/s^2, one
    column); ``series["/pph/eddy"]`` per block of ``POSE_BLOCK`` samples the mean pose
    (m, rad; 6 columns) then its RMS deviation (6 columns); the other topics only their
    sample accounting.
    """

    path: Path
    series: dict[str, StrutSeries]
    driver_status: dict[str, str] = field(default_factory=dict)
    driver_statuses: list[dict[str, str]] = field(default_factory=list)
    """Every driver report, in the bag's order (``driver_status``: the last)."""
    notch_statuses: list[dict[str, str]] = field(default_factory=list)
    weights_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 6, 2)))
    control_on_sample: int | None = None
    control_source: str = "none"
    record: RunRecord | None = None
    recovered: str = ""
    bad_messages: dict[str, int] = field(default_factory=dict)
    frequencies: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    """Recorded frequency topics: (sample index (N,), Hz (N, K)) (``BagContent.frequencies``)."""
    sensitivity: list[tuple[int, dict[str, np.ndarray]]] = field(default_factory=list)
    """Recorded ``/pph/notch_sensitivity`` predictions: (sample, {row: values})."""

    @property
    def accel(self) -> StrutSeries:
        """The /pph/accel series (values: z acceleration, m/s^2)."""
        return self.series[ACCEL_TOPIC]

    @property
    def z(self) -> np.ndarray:
        """Top plate z acceleration (m/s^2) per received sample."""
        return self.accel.values[:, 0]

    def notch_tones(self) -> list[float]:
        """Tones of the notch controller as it last reported them (Hz), or []."""
        for status in reversed(self.notch_statuses):
            if "tones_hz" in status:
                return [float(x) for x in json.loads(status["tones_hz"])]
        return []

    def run_samples(self) -> int:
        """Samples of the run: [0, this), from the driver and every topic's last sample."""
        last = max((s.last_sample for s in self.series.values()), default=-1)
        return max(int(self.driver_status.get("samples", 0) or 0), last + 1)


def z_columns(geometry: CubicHexapodGeometry) -> np.ndarray:
    """(6, 1) matrix: strut accelerations (m/s^2) @ it = top plate z acceleration."""
    return geometry.platform_from_struts(np.eye(6))[:, 2:3]


def pose_columns(model: ModelConfig) -> np.ndarray:
    """(6, 6) matrix: eddy-current gaps (m) @ it = the top plate's pose (m, rad)."""
    height = float(model.geometry.top_joints_m[0, 2])
    return EddySensorArray(model.eddy, height).pose(np.eye(6))


def load_signals(bag_path: str | Path, model: ModelConfig,
                 control_on_s: float | None = None) -> BagSignals:
    """Read the bag in one pass; find the run record and when control went on."""
    none = np.zeros((6, 0))
    keep = {topic: Keep(columns=none, timestamps=False) for topic in STRUT_TOPICS}
    keep[ACCEL_TOPIC] = Keep(columns=z_columns(model.geometry))
    keep["/pph/eddy"] = Keep(columns=pose_columns(model), timestamps=False,
                                    block=POSE_BLOCK)
    keep["/pph/notch_command"] = Keep(columns=none, every=COMMAND_EVERY)
    content = read_bag(bag_path, keep, FS, weights_every=WEIGHTS_EVERY)
    signals = BagSignals(Path(bag_path), content.strut, recovered=content.recovered,
                         bad_messages=content.bad_messages, frequencies=content.frequencies,
                         sensitivity=content.sensitivity)
    for _, name, values in content.diagnostics:
        if name == DRIVER_STATUS:
            signals.driver_status = values
            signals.driver_statuses.append(values)
        elif name == NOTCH_STATUS:
            signals.notch_statuses.append(values)
    signals.weights_index, signals.weights = content.weights_index, content.weights
    if RUN_RECORD_KEY in content.custom_data:
        signals.record = RunRecord.from_json(content.custom_data[RUN_RECORD_KEY])
    _find_control_switch(signals, control_on_s, content.parameter_events)
    return signals


def _find_control_switch(signals: BagSignals, control_on_s: float | None,
                         events: list[tuple[int, Any]]) -> None:
    """Control-on sample: CLI value, notch diagnostics, parameter event, run record, none.

    ``/parameter_events`` carry only receive times; they are used (placed on the sample
    grid of the accelerometer timestamps) only when the notch diagnostics are absent.
    """
    if control_on_s is not None:
        signals.control_on_sample, signals.control_source = int(round(control_on_s * FS)), "cli"
        return
    for status in signals.notch_statuses:
        since = int(status.get("enabled_since_sample", "-1"))
        if since >= 0 and status.get("state") in (NotchState.ADAPTING, NotchState.ENABLED):
            signals.control_on_sample, signals.control_source = since, "notch diagnostics"
            return
    switched = [t for t, v in events if v is True]
    accel = signals.accel
    if switched and accel.timestamp_ns.size:
        nearest = min(int(np.searchsorted(accel.timestamp_ns, switched[-1])),
                      accel.timestamp_ns.size - 1)
        signals.control_on_sample = int(accel.sample_index[nearest])
        signals.control_source = "parameter event"
    elif signals.record is not None and signals.record.control_on_sample >= 0:
        signals.control_on_sample = signals.record.control_on_sample
        signals.control_source = "run record"
