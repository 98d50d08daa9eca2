"""A /diagnostics status written by hand (diagnostics_cdr) against rclpy's own messages."""

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import deserialize_message, serialize_message

from hexapod_vibration.diagnostics_cdr import (
    ERROR,
    OK,
    STALE,
    WARN,
    encode_diagnostics_cdr,
    format_value,
)
from hexapod_vibration.ros.diagnostics import HARDWARE_ID, diagnostic_array

VALUES = {
    "none": {},
    "mixed": {"rate_hz": 999.98765432, "held": True, "late_commands": 3, "mode": "realtime"},
    "unicode": {"k\u00e9y": "\u00fc \u00e9", "": ""},
    "driver-sized": {f"cpu_us_per_sample stage {i}": i * 0.37 for i in range(61)},
}


def _rclpy_message(level, name, message, hardware_id, values, sec, nanosec):
    status = DiagnosticStatus(level=bytes([level]), name=name, message=message,
                              hardware_id=hardware_id,
                              values=[KeyValue(key=k, value=format_value(v))
                                      for k, v in values.items()])
    msg = DiagnosticArray(status=[status])
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return msg


@pytest.mark.parametrize("values", VALUES.values(), ids=VALUES.keys())
@pytest.mark.parametrize("message", ["ok", "", "stale: notch", "abc"])
@pytest.mark.parametrize("level", [OK, WARN, ERROR, STALE])
def test_bytes_read_back_as_the_message_rclpy_builds(values, message, level):
    args = (level, "pph_driver: loop", message, HARDWARE_ID, values, 12, 345_000_000)
    raw = encode_diagnostics_cdr(*args)
    expected = _rclpy_message(*args)
    assert deserialize_message(raw, DiagnosticArray) == expected
    # The same layout byte for byte but the padding (rclpy leaves it uninitialised).
    assert len(raw) == len(serialize_message(expected))


def test_padding_is_zero_and_the_message_ends_at_the_last_nul():
    raw = encode_diagnostics_cdr(WARN, "n", "m", "h", {"a": "b"}, 0, 0)
    assert raw.endswith(b"\x02\x00\x00\x00b\x00")       # the last string: length 2, "b", NUL
    assert raw[4:12] == bytes(8)                          # stamp 0 s, 0 ns
    assert raw[12:20] == b"\x01\x00\x00\x00\x00\x00\x00\x00"   # empty frame id, padded
    assert raw[24:28] == b"\x01\x00\x00\x00"                   # the level byte, padded


def test_the_nodes_status_is_stamped_at_its_sample():
    raw = diagnostic_array("pph_driver: loop", True, "late", {"sample": 1500}, 1500)
    msg = deserialize_message(raw, DiagnosticArray)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 500_000_000)
    status = msg.status[0]
    assert status.level == DiagnosticStatus.WARN and status.hardware_id == HARDWARE_ID
    assert [(kv.key, kv.value) for kv in status.values] == [("sample", "1500")]


@pytest.mark.parametrize("value, text", [(0.1 + 0.2, "0.3"), (1e-9, "1e-09"), (True, "true"),
                                         (7, "7"), ("x", "x"), (float("nan"), "nan")])
def test_format_value(value, text):
    assert format_value(value) == text
