"""The CDR bytes of a node's ``/diagnostics`` status, written by hand, without ROS.

The 1 kHz nodes publish one ``diagnostic_msgs/DiagnosticArray`` a simulated second, with
one status of 40-70 key/value pairs. Built as rclpy messages (a ``KeyValue`` object per
pair, its fields checked as they are set) and serialized by rclpy, that took about 0.1 ms
warm and 0.5-0.7 ms of the driver's CPU in the realtime graph, in the sample after which
the driver publishes it: on two cores without real-time priority the samples that followed
missed their commands more often than the others. :func:`encode_diagnostics_cdr` writes the
message in one pass over the pairs, its fields where rclpy puts them (tested: rclpy reads
the bytes back as the message it builds, and its own serialization has the same length;
its padding bytes are uninitialised, these are zero); the node publishes them serialized.

Plain CDR (XCDR1), little endian: the encapsulation header, then the header's stamp and
frame id, the status count, and per status its level byte (padded to 4), name, message,
hardware id and pairs; every string is its length (NUL included), text and NUL, and the
next field starts at a multiple of 4 (a string's padding is left out at the very end).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping

from hexapod_vibration.cdr import cdr_string, stamp_cdr

OK, WARN, ERROR, STALE = 0, 1, 2, 3
"""``diagnostic_msgs/DiagnosticStatus`` levels."""

_COUNT = struct.Struct("<I")               # a sequence's length
_ONE_STATUS = _COUNT.pack(1)
_LEVEL = {level: struct.pack("<B3x", level) for level in (OK, WARN, ERROR, STALE)}
_EMPTY_FRAME_ID = cdr_string(b"")


def format_value(value: object) -> str:
    """Diagnostics value text: floats with 6 significant digits, bools lower case."""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value).lower() if isinstance(value, bool) else str(value)


def encode_diagnostics_cdr(level: int, name: str, message: str, hardware_id: str,
                           values: Mapping[str, object], sec: int, nanosec: int) -> bytes:
    """A DiagnosticArray of one status, stamped ``sec``/``nanosec`` (s, ns), as CDR bytes.

    Args:
        level: The status level (:data:`OK`, :data:`WARN`, :data:`ERROR`, :data:`STALE`).
        name: The status's name (``<node>: <what>``).
        message: Its one-line summary.
        hardware_id: What it describes (the simulated hexapod, a bag).
        values: Its key/value pairs, each value written as :func:`format_value` does.
        sec: The header's stamp, whole seconds (s).
        nanosec: The stamp's rest (ns, below 1e9); the frame id is empty.
    """
    parts = [stamp_cdr(sec, nanosec), _EMPTY_FRAME_ID, _ONE_STATUS, _LEVEL[level],
             cdr_string(name.encode()), cdr_string(message.encode()),
             cdr_string(hardware_id.encode()), _COUNT.pack(len(values))]
    for key, value in values.items():
        text = format_value(value).encode()
        parts += (cdr_string(key.encode()), cdr_string(text))
    raw = b"".join(parts)
    if not values:                     # the message ends with the pairs' count
        return raw
    return raw[:len(raw) - (-(len(text) + 1) % 4)]   # at the last string's NUL, as rclpy's
