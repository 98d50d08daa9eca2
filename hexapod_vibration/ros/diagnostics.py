"""``/diagnostics`` messages and sim-time stamps shared by the nodes.

The driver's ``/clock`` bytes are :func:`hexapod_vibration.ros.rclpy_internals.clock_cdr`.
"""

from __future__ import annotations

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from hexapod_vibration.contract import SAMPLE_RATE_HZ, sample_sim_time

HARDWARE_ID = "pph_sim"


def sample_time(sample: int, sample_rate_hz: float = SAMPLE_RATE_HZ) -> Time:
    """Sim time of loop sample ``sample`` (n / fs s), as ``builtin_interfaces/Time``."""
    sec, nanosec = sample_sim_time(sample, sample_rate_hz)
    return Time(sec=sec, nanosec=nanosec)


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
