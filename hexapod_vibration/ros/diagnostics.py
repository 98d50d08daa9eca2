"""``/diagnostics`` messages and sim-time stamps shared by the nodes."""

from __future__ import annotations

import struct

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

HARDWARE_ID = "pph_sim"


def _sec_nanosec(sample: int, sample_rate_hz: float) -> tuple[int, int]:
    """Sim time of loop sample ``sample`` (n / fs s, 0 before sample 0) as (s, ns)."""
    return divmod(int(round(max(sample, 0) * 1e9 / sample_rate_hz)), 1_000_000_000)


def sample_time(sample: int, sample_rate_hz: float = 1000.0) -> Time:
    """Sim time of loop sample ``sample`` (n / fs s), as ``builtin_interfaces/Time``."""
    sec, nanosec = _sec_nanosec(sample, sample_rate_hz)
    return Time(sec=sec, nanosec=nanosec)


_CLOCK_CDR = struct.Struct("<4siI")     # encapsulation (LE CDR), sec (int32), nanosec


def clock_cdr(sample: int, sample_rate_hz: float = 1000.0) -> bytes:
    """``rosgraph_msgs/Clock`` at :func:`sample_time` as serialized (CDR) bytes.

    What rclpy serializes from ``Clock(clock=sample_time(sample))`` (tested), built without
    the Python message: the driver publishes it every sample.
    """
    return _CLOCK_CDR.pack(b"\x00\x01\x00\x00", *_sec_nanosec(sample, sample_rate_hz))


def format_value(value: object) -> str:
    """Diagnostics value text: floats with 6 significant digits, bools lower case."""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value).lower() if isinstance(value, bool) else str(value)


def diagnostic_array(name: str, warn: bool, message: str, values: dict[str, object],
                     sample: int) -> DiagnosticArray:
    """One status (OK or WARN) with ``values`` as key/value pairs, stamped at ``sample``."""
    status = DiagnosticStatus(level=DiagnosticStatus.WARN if warn else DiagnosticStatus.OK,
                              name=name, message=message, hardware_id=HARDWARE_ID,
                              values=[KeyValue(key=k, value=format_value(v))
                                      for k, v in values.items()])
    msg = DiagnosticArray(status=[status])
    msg.header.stamp = sample_time(sample)
    return msg
