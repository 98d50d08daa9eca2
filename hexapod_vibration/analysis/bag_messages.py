"""Messages of a bag decoded: strut arrays, the sensitivity table, parameter values.

Little-endian CDR Float64MultiArrays (what ROS 2 middlewares on x86 and ARM write) are read
by the package's codec (:func:`hexapod_vibration.cdr.decode_float64_array`), a few
microseconds a message; other encapsulations go through rosbags' deserializer.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from rosbags.serde import SerdeError

from hexapod_vibration.analysis.bag_format import STRUT_MSGTYPE, typestore
from hexapod_vibration.cdr import LITTLE_ENDIAN_CDR, MAX_BAG_SAMPLE_INDEX, decode_float64_array
from hexapod_vibration.contract import (
    SENSITIVITY_ROWS_PREFIX,
    STRUT_COUNT,
    InvalidStrutMessage,
    parse_sample_label,
)

DECODE_ERRORS = (struct.error, ValueError, IndexError, UnicodeDecodeError, SerdeError,
                  AssertionError, KeyError, TypeError, OverflowError, MemoryError)


def decode_strut_message(data: bytes | memoryview) -> tuple[np.ndarray, int | None]:
    """Six values and the in-band sample index of a serialized Float64MultiArray.

    Little-endian CDR (what ROS 2 middlewares on x86 and ARM write) is decoded directly,
    a few microseconds a message; other encapsulations go through rosbags' deserializer.

    Raises:
        InvalidStrutMessage: Undecodable bytes, not six finite values, a garbled or
            out-of-range sample label.
    """
    try:
        values, labels = decode_array(data)
    except DECODE_ERRORS as err:
        raise InvalidStrutMessage(f"undecodable message ({err.__class__.__name__})") from None
    if values.shape != (STRUT_COUNT,):
        raise InvalidStrutMessage(f"expected {STRUT_COUNT} strut values, got {values.size}")
    if not np.isfinite(values).all():
        raise InvalidStrutMessage("non-finite strut value")
    if len(labels) < 2:
        return values, None
    index = parse_sample_label(labels[1])
    if index >= MAX_BAG_SAMPLE_INDEX:
        raise InvalidStrutMessage(f"sample index {index} out of range")
    return values, index


def decode_array(data: bytes | memoryview) -> tuple[np.ndarray, list[str]]:
    """Values and dimension labels of a serialized Float64MultiArray.

    Little-endian CDR is decoded directly; other encapsulations go through rosbags.
    """
    raw = bytes(data)
    if raw[:2] in LITTLE_ENDIAN_CDR:
        return decode_float64_array(raw)
    msg = typestore().deserialize_cdr(raw, STRUT_MSGTYPE)
    return np.asarray(msg.data, dtype=np.float64), [d.label for d in msg.layout.dim]


def table_of_message(msg: Any) -> tuple[int, dict[str, np.ndarray]]:
    """(sample index, {row name: values}) of a ``/pph/notch_sensitivity`` message.

    Raises:
        ValueError: Not the layout ``ros.messages.make_table_array`` writes.
    """
    dims = msg.layout.dim
    if len(dims) < 3 or not dims[0].label.startswith(SENSITIVITY_ROWS_PREFIX):
        raise ValueError("not a table message")
    names = dims[0].label[len(SENSITIVITY_ROWS_PREFIX):].split(",")
    table = np.asarray(msg.data, dtype=np.float64).reshape(len(names), int(dims[1].size))
    return parse_sample_label(dims[2].label), dict(zip(names, table, strict=True))


# ParameterValue.type -> field holding the value (rcl_interfaces/msg/ParameterType).
_PARAMETER_FIELDS = {
    1: "bool_value",
    2: "integer_value",
    3: "double_value",
    4: "string_value",
    5: "byte_array_value",
    6: "bool_array_value",
    7: "integer_array_value",
    8: "double_array_value",
    9: "string_array_value",
}


def parameter_value(value: Any) -> Any:
    """Python value of an ``rcl_interfaces/msg/ParameterValue`` (None when not set)."""
    field = _PARAMETER_FIELDS.get(int(value.type))
    if field is None:
        return None
    result = getattr(value, field)
    return result.tolist() if isinstance(result, np.ndarray) else result
