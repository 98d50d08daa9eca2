"""Bags written independently (rosbags Writer) read back exactly; damage is reported."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from hexapod_vibration.analysis.bag_files import BagError
from hexapod_vibration.analysis.bag_format import BAG_VERSION, STRUT_MSGTYPE, typestore
from hexapod_vibration.analysis.bag_reading import (
    read_clock,
    read_parameter_events,
    read_strut_topics,
)
from hexapod_vibration.analysis.bag_writer import write_strut_bag

STORAGES = ["mcap", "sqlite3"]
PLUGINS = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
WALL_CLOCK_NS = 1_763_000_000_123_456_789  # a bag recorded at wall-clock time


def _values(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 1.0, size=(n, 6))


def _sample_bag(path: Path, storage: str, **kwargs) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    series = {
        "/pph/accel": (np.arange(500), _values(500, 1)),
        "/pph/eddy": (np.arange(3, 500), _values(497, 2)),
        "/pph/notch_command": (np.arange(0, 500, 2), _values(250, 3)),
    }
    write_strut_bag(path, series, storage=storage, **kwargs)
    return series


def _data_file(bag: Path) -> Path:
    return next(p for p in bag.iterdir() if p.name != "metadata.yaml")


def _write_raw(path: Path, storage: str, messages: list[tuple[str, str, int, object]]) -> None:
    """Write (topic, msgtype, timestamp, rosbags message) records with rosbags directly."""
    store = typestore()
    with Writer(path, version=BAG_VERSION, storage_plugin=PLUGINS[storage]) as writer:
        conns = {}
        for topic, msgtype, stamp, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], stamp, store.serialize_cdr(msg, msgtype))


def _float_array(values, labels):
    types = typestore().types
    dims = [
        types["std_msgs/msg/MultiArrayDimension"](label=lbl, size=6, stride=6) for lbl in labels
    ]
    layout = types["std_msgs/msg/MultiArrayLayout"](dim=dims, data_offset=0)
    return types[STRUT_MSGTYPE](layout=layout, data=np.asarray(values, dtype=np.float64))


@pytest.mark.parametrize("storage", STORAGES)
def test_round_trip_in_band(tmp_path, storage):
    written = _sample_bag(tmp_path / "bag", storage)
    result = read_strut_topics(tmp_path / "bag")
    assert set(result) == set(written)
    for topic, (index, values) in written.items():
        series = result[topic]
        assert series.index_source == "in-band"
        assert series.sample_index.dtype == np.int64
        assert series.values.dtype == np.float64
        np.testing.assert_array_equal(series.sample_index, index)
        np.testing.assert_array_equal(series.values, values)
        np.testing.assert_array_equal(series.timestamp_ns, index * 1_000_000)
        assert series.duplicate_samples == 0
        assert series.invalid_messages == 0
    assert result["/pph/accel"].missing_samples == 0
    assert result["/pph/notch_command"].missing_samples == 249


@pytest.mark.parametrize("storage", STORAGES)
def test_without_in_band_index_uses_timestamps(tmp_path, storage):
    written = _sample_bag(
        tmp_path / "bag", storage, in_band_index=False, start_time_ns=WALL_CLOCK_NS
    )
    result = read_strut_topics(tmp_path / "bag")
    for topic, (index, values) in written.items():
        series = result[topic]
        assert series.index_source == "timestamp"
        # t0 is common to all topics: /pph/eddy keeps its 3-sample offset to /pph/accel.
        np.testing.assert_array_equal(series.sample_index, index)
        np.testing.assert_array_equal(series.values, values)


def test_timestamp_index_follows_sample_rate(tmp_path):
    index = np.arange(100)
    write_strut_bag(
        tmp_path / "bag",
        {"/pph/accel": (index, _values(100, 4))},
        sample_rate_hz=500.0,
        in_band_index=False,
    )
    series = read_strut_topics(tmp_path / "bag", sample_rate_hz=500.0)["/pph/accel"]
    np.testing.assert_array_equal(series.sample_index, index)
    doubled = read_strut_topics(tmp_path / "bag", sample_rate_hz=1000.0)["/pph/accel"]
    np.testing.assert_array_equal(doubled.sample_index, 2 * index)
    assert doubled.missing_samples == 99


@pytest.mark.parametrize("in_band", [True, False])
def test_duplicates_dropped_and_gaps_counted(tmp_path, in_band):
    index = np.array([10, 11, 12, 12, 15, 16, 16, 16, 17])
    values = _values(index.size, 5)
    values[3] = values[2]  # a repeated sample carries the same values
    values[6] = values[7] = values[5]
    write_strut_bag(tmp_path / "bag", {"/pph/accel": (index, values)}, in_band_index=in_band)
    series = read_strut_topics(tmp_path / "bag")["/pph/accel"]
    expected = [10, 11, 12, 15, 16, 17] if in_band else [0, 1, 2, 5, 6, 7]
    np.testing.assert_array_equal(series.sample_index, expected)
    np.testing.assert_array_equal(series.values, values[[0, 1, 2, 4, 5, 8]])
    assert series.duplicate_samples == 3
    assert series.missing_samples == 2


@pytest.mark.parametrize("storage", STORAGES)
def test_unusable_messages_are_skipped_and_counted(tmp_path, storage):
    good = np.arange(6.0)
    messages = [
        ("/pph/accel", STRUT_MSGTYPE, 0, _float_array(good, ["strut", "sample:0"])),
        ("/pph/accel", STRUT_MSGTYPE, 1, _float_array(np.arange(5.0), ["strut", "sample:1"])),
        (
            "/pph/accel",
            STRUT_MSGTYPE,
            2,
            _float_array([0, 1, np.nan, 3, 4, 5], ["strut", "sample:2"]),
        ),
        ("/pph/accel", STRUT_MSGTYPE, 3, _float_array(good, ["strut", "sample:x3"])),
        ("/pph/accel", STRUT_MSGTYPE, 4, _float_array(good, ["strut"])),  # no index, others have
        ("/pph/accel", STRUT_MSGTYPE, 5, _float_array(good + 5, ["strut", "sample:5"])),
    ]
    _write_raw(tmp_path / "bag", storage, messages)
    series = read_strut_topics(tmp_path / "bag")["/pph/accel"]
    assert series.invalid_messages == 4
    np.testing.assert_array_equal(series.sample_index, [0, 5])
    np.testing.assert_array_equal(series.values, [good, good + 5])
    assert series.missing_samples == 4


def test_bag_file_path_is_accepted(tmp_path):
    _sample_bag(tmp_path / "bag", "mcap")
    result = read_strut_topics(_data_file(tmp_path / "bag"))
    assert len(result["/pph/accel"]) == 500


def test_missing_accel_lists_topics(tmp_path):
    write_strut_bag(tmp_path / "bag", {"/pph/eddy": (np.arange(10), _values(10, 6))})
    with pytest.raises(BagError, match=r"has no /pph/accel.*/pph/eddy \(std_msgs/msg/Float64"):
        read_strut_topics(tmp_path / "bag")
    only_eddy = read_strut_topics(tmp_path / "bag", topics=("/pph/eddy",))
    assert len(only_eddy["/pph/eddy"]) == 10


def test_wrong_message_type_is_reported(tmp_path):
    clock = typestore().types["rosgraph_msgs/msg/Clock"]
    time_type = typestore().types["builtin_interfaces/msg/Time"]
    msg = clock(clock=time_type(sec=1, nanosec=0))
    _write_raw(tmp_path / "bag", "mcap", [("/pph/accel", "rosgraph_msgs/msg/Clock", 0, msg)])
    with pytest.raises(BagError, match="/pph/accel has type rosgraph_msgs/msg/Clock"):
        read_strut_topics(tmp_path / "bag")


def test_missing_bag(tmp_path):
    with pytest.raises(BagError, match=f'bag not found: {tmp_path / "nope"}'):
        read_strut_topics(tmp_path / "nope")


def test_directory_without_metadata(tmp_path):
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "bag.mcap").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(BagError, match="no metadata.yaml"):
        read_strut_topics(tmp_path / "bag")


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("fraction", [0.0, 0.3, 0.9])
def test_truncated_bag(tmp_path, storage, fraction):
    bag = tmp_path / "bag"
    _sample_bag(bag, storage)
    data = _data_file(bag)
    with data.open("r+b") as handle:
        handle.truncate(int(data.stat().st_size * fraction))
    with pytest.raises(BagError, match=str(bag)):
        read_strut_topics(bag)


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("position", [0.3, 0.6])
def test_corrupt_bag(tmp_path, storage, position):
    bag = tmp_path / "bag"
    _sample_bag(bag, storage)
    data = _data_file(bag)
    garbage = np.random.default_rng(11).integers(0, 256, size=4000, dtype=np.uint8).tobytes()
    with data.open("r+b") as handle:
        handle.seek(int(data.stat().st_size * position))
        handle.write(garbage)
    with pytest.raises(BagError, match=f"{bag}.*(truncated|corrupt|undecodable)"):
        read_strut_topics(bag)


def test_corrupt_metadata(tmp_path):
    bag = tmp_path / "bag"
    _sample_bag(bag, "mcap")
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed")
    with pytest.raises(BagError, match=f"cannot open bag {bag}"):
        read_strut_topics(bag)


def test_bags_are_never_overwritten(tmp_path):
    _sample_bag(tmp_path / "bag", "mcap")
    before = {p.name: p.stat().st_size for p in (tmp_path / "bag").iterdir()}
    with pytest.raises(BagError, match="exists already"):
        _sample_bag(tmp_path / "bag", "mcap")
    assert {p.name: p.stat().st_size for p in (tmp_path / "bag").iterdir()} == before


def _parameter_event(node: str, new: dict, changed: dict, stamp_s: int):
    types = typestore().types
    value_type = types["rcl_interfaces/msg/ParameterValue"]
    param_type = types["rcl_interfaces/msg/Parameter"]

    def value(v):
        fields = dict(
            bool_value=False,
            integer_value=0,
            double_value=0.0,
            string_value="",
            byte_array_value=np.zeros(0, np.uint8),
            bool_array_value=np.zeros(0, bool),
            integer_array_value=np.zeros(0, np.int64),
            double_array_value=np.zeros(0, np.float64),
            string_array_value=[],
        )
        if isinstance(v, bool):
            return value_type(type=1, **{**fields, "bool_value": v})
        if isinstance(v, float):
            return value_type(type=3, **{**fields, "double_value": v})
        return value_type(type=8, **{**fields, "double_array_value": np.asarray(v, np.float64)})

    return types["rcl_interfaces/msg/ParameterEvent"](
        stamp=types["builtin_interfaces/msg/Time"](sec=stamp_s, nanosec=0),
        node=node,
        new_parameters=[param_type(name=k, value=value(v)) for k, v in new.items()],
        changed_parameters=[param_type(name=k, value=value(v)) for k, v in changed.items()],
        deleted_parameters=[],
    )


@pytest.mark.parametrize("storage", STORAGES)
def test_parameter_events_and_clock(tmp_path, storage):
    event_type = "rcl_interfaces/msg/ParameterEvent"
    clock_type = typestore().types["rosgraph_msgs/msg/Clock"]
    time_type = typestore().types["builtin_interfaces/msg/Time"]
    events = [
        _parameter_event("/notch_controller", {"enabled": False, "mu": 0.01}, {}, 1),
        _parameter_event("/pointing_controller", {}, {"enabled": True}, 2),
        _parameter_event("/notch_controller", {}, {"mu": 0.002}, 3),
        _parameter_event("/notch_controller", {}, {"enabled": True}, 4),
        _parameter_event("/notch_controller", {}, {"tone_frequencies_hz": [40.0, 80.0]}, 5),
    ]
    messages = [("/parameter_events", event_type, (i + 1) * 10**9, e) for i, e in enumerate(events)]
    messages += [
        ("/clock", "rosgraph_msgs/msg/Clock", 7, clock_type(clock=time_type(sec=2, nanosec=5))),
        ("/pph/accel", STRUT_MSGTYPE, 8, _float_array(np.zeros(6), ["strut", "sample:0"])),
    ]
    _write_raw(tmp_path / "bag", storage, messages)
    assert read_parameter_events(tmp_path / "bag") == [(10**9, False), (4 * 10**9, True)]
    assert read_parameter_events(tmp_path / "bag", name="mu") == [(10**9, 0.01), (3 * 10**9, 0.002)]
    assert read_parameter_events(tmp_path / "bag", name="tone_frequencies_hz") == [
        (5 * 10**9, [40.0, 80.0])
    ]
    stamps, clock = read_clock(tmp_path / "bag")
    assert stamps.tolist() == [7] and clock.tolist() == [2_000_000_005]


def test_parameter_events_and_clock_absent(tmp_path):
    _sample_bag(tmp_path / "bag", "sqlite3")
    assert read_parameter_events(tmp_path / "bag") == []
    stamps, clock = read_clock(tmp_path / "bag")
    assert stamps.size == 0 and clock.size == 0


def test_readable_from_a_copy(tmp_path):
    """A bag moved elsewhere stays readable (relative file paths in metadata.yaml)."""
    _sample_bag(tmp_path / "bag", "sqlite3")
    shutil.copytree(tmp_path / "bag", tmp_path / "moved")
    shutil.rmtree(tmp_path / "bag")
    assert len(read_strut_topics(tmp_path / "moved")["/pph/accel"]) == 500


def test_fewer_messages_than_metadata_lists_is_corruption(tmp_path):
    """A data file shorter than its metadata.yaml says (e.g. a lost MCAP chunk) is an error."""
    bag = tmp_path / "bag"
    _sample_bag(bag, "mcap")
    metadata = bag / "metadata.yaml"
    text = metadata.read_text()
    assert text.count("message_count: 500") == 1
    metadata.write_text(text.replace("message_count: 500", "message_count: 600"))
    with pytest.raises(BagError, match="read 500 of the 600 messages on /pph/accel"):
        read_strut_topics(bag)
