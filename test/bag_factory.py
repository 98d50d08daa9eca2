"""Hand-made bags for the analysis tests: strut topics, notch diagnostics, a run record.

Written with rosbags' own Writer (not the package's recorder), stamped on the sample grid.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from hexapod_vibration.analysis.bag_format import (
    BAG_VERSION,
    DIAGNOSTICS_MSGTYPE,
    RUN_RECORD_KEY,
    STRUT_MSGTYPE,
    typestore,
)
from hexapod_vibration.core.model.geometry import CubicHexapodGeometry
from hexapod_vibration.core.spectrum import G0

FS = 1000.0
GEO = CubicHexapodGeometry()


def struts_from_z(z: np.ndarray, seed: int = 0, noise: float = 1e-6) -> np.ndarray:
    """Six strut accelerations whose top-plate z component is ``z`` (m/s^2)."""
    rng = np.random.default_rng(seed)
    platform = np.zeros((z.size, 6))
    platform[:, 2] = z
    platform += rng.normal(0.0, noise, platform.shape)
    return platform @ GEO.top_jacobian.T


def tone(level_db: float, f: float, n: int, phase: float = 0.0) -> np.ndarray:
    """A sinusoid of RMS ``level_db`` dB re 1 g at ``f`` Hz over n samples."""
    t = np.arange(n) / FS
    return np.sqrt(2.0) * G0 * 10 ** (level_db / 20.0) * np.cos(2 * np.pi * f * t + phase)


def strut_cdr(values: np.ndarray, index: int | None) -> bytes:
    store = typestore()
    dim = store.types["std_msgs/msg/MultiArrayDimension"]
    dims = [dim(label="strut", size=6, stride=6)]
    if index is not None:
        dims.append(dim(label=f"sample:{index}", size=1, stride=1))
    layout = store.types["std_msgs/msg/MultiArrayLayout"](dim=dims, data_offset=0)
    msg = store.types[STRUT_MSGTYPE](layout=layout, data=np.asarray(values, np.float64))
    return bytes(store.serialize_cdr(msg, STRUT_MSGTYPE))


def array_cdr(values: np.ndarray, labels: list[tuple[str, int, int]]) -> bytes:
    """Any Float64MultiArray: values and (label, size, stride) dimensions."""
    store = typestore()
    dim = store.types["std_msgs/msg/MultiArrayDimension"]
    layout = store.types["std_msgs/msg/MultiArrayLayout"](
        dim=[dim(label=a, size=b, stride=c) for a, b, c in labels], data_offset=0)
    msg = store.types[STRUT_MSGTYPE](layout=layout,
                                     data=np.asarray(values, np.float64).reshape(-1))
    return bytes(store.serialize_cdr(msg, STRUT_MSGTYPE))


def frequencies_cdr(values_hz, index: int) -> bytes:
    """A frequency-topic message (``ros.messages.make_vector_array``'s layout)."""
    values = np.asarray(values_hz, np.float64).reshape(-1)
    return array_cdr(values, [("frequency_hz", values.size, values.size),
                              (f"sample:{index}", 1, 1)])


def diagnostics_cdr(name: str, values: dict[str, str], sample: int) -> bytes:
    store = typestore()
    t = store.types
    status = t["diagnostic_msgs/msg/DiagnosticStatus"](
        level=0, name=name, message="", hardware_id="pph_sim",
        values=[t["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in values.items()])
    stamp = t["builtin_interfaces/msg/Time"](sec=sample // 1000, nanosec=(sample % 1000) * 10**6)
    header = t["std_msgs/msg/Header"](stamp=stamp, frame_id="")
    msg = t[DIAGNOSTICS_MSGTYPE](header=header, status=[status])
    return bytes(store.serialize_cdr(msg, DIAGNOSTICS_MSGTYPE))


def notch_status(sample: int, state: str, tones: list[float], on: int = -1,
                 ident: tuple[int, int] | None = None) -> dict[str, str]:
    """The notch controller's /diagnostics values (with identification keys if given)."""
    values = {"state": state, "enabled_since_sample": str(on), "last_sample": str(sample),
              "tones_hz": str([float(f) for f in tones])}
    if ident is not None:
        values["identification_start_sample"] = str(ident[0])
        values["identification_end_sample"] = str(ident[1])
    return values


def write_bag(path: Path, accel: np.ndarray, index: np.ndarray | None = None,
              statuses: list[tuple[int, dict[str, str]]] = (),
              run_record: str = "", storage: str = "mcap",
              extra: list[tuple[str, int, bytes]] = (),
              topics: dict[str, list[tuple[int, bytes]]] | None = None) -> Path:
    """A bag with /pph/accel (in-band index), notch statuses and optional run record.

    ``extra``: (topic, sample, raw CDR bytes) written as they are (bad messages).
    ``topics``: other Float64MultiArray topics, {topic: [(sample, raw CDR bytes)]}.
    """
    index = np.arange(accel.shape[0]) if index is None else np.asarray(index)
    store = typestore()
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    with Writer(path, version=BAG_VERSION, storage_plugin=plugin) as writer:
        if run_record:
            writer.set_custom_data(RUN_RECORD_KEY, run_record)
        conn = writer.add_connection("/pph/accel", STRUT_MSGTYPE, typestore=store)
        diag = writer.add_connection("/diagnostics", DIAGNOSTICS_MSGTYPE, typestore=store)
        status_at = dict(statuses)
        extras: dict[int, list[bytes]] = {}
        for _topic, sample, raw in extra:
            extras.setdefault(sample, []).append(raw)
        for topic, messages in (topics or {}).items():
            other = writer.add_connection(topic, STRUT_MSGTYPE, typestore=store)
            for n, raw in messages:
                writer.write(other, n * 10**6, raw)
        for n, row in zip(index.tolist(), accel, strict=True):
            writer.write(conn, n * 10**6, strut_cdr(row, n))
            for raw in extras.get(n, []):
                writer.write(conn, n * 10**6, raw)
            if n in status_at:
                writer.write(diag, n * 10**6, diagnostics_cdr("notch_controller",
                                                              status_at[n], n))
    return path
