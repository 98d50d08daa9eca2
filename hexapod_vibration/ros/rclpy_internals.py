"""Everything below rclpy's public API, and the loop's hand-written CDR, in one module.

The 1 kHz loop avoids rclpy's conversion between Python messages and their C form, which
costs more than a message's whole DDS delivery within a process (numbers below). That
takes four things rclpy does not offer publicly:

- a persistent wait set over the loop subscriptions (``rclpy_implementation.WaitSet``);
- taking a subscription's queued messages serialized, directly from its handle
  (``Subscription.handle.take_message``), as rclpy's executors do internally;
- publishing serialized bytes without rclpy's per-call type check
  (``Publisher.handle.publish_raw``);
- ``RCLError``, what those calls raise (``rclpy._rclpy_pybind11``).

and the CDR bytes of the loop's messages written and read by hand
(:func:`encode_strut_cdr`, :func:`decode_strut_cdr`, :func:`clock_cdr`): exactly what rclpy
serializes (tested against it on every run of the suite).

These were verified against rclpy :data:`VERIFIED_RCLPY_VERSION`. With another version,
with one of the private APIs missing, or with ``HEXAPOD_RCLPY_PUBLIC_API=1`` in the
environment, :func:`fast_path` is False and the callers use the public API instead
(rclpy's executor for the loop subscriptions, ``Publisher.publish``, ``serialize_message``),
which is slower but has the same results; the reason is logged once per process.

:func:`decode_strut_cdr` is used on both paths: it is the gate every received loop message
goes through (loop subscriptions are raw), and it uses no rclpy API at all. rclpy's own
``deserialize_message`` cannot be that gate: it raises ``RMWError`` on malformed bytes and
turns an impossible layout (a huge ``dims`` count) into six garbage numbers.
"""

from __future__ import annotations

import functools
import importlib.metadata
import math
import os
import re
import struct
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rclpy.logging
from rclpy.exceptions import InvalidHandle

from hexapod_vibration.contract import (
    RUN_LABEL_PREFIX,
    SAMPLE_LABEL_PREFIX,
    SAMPLE_RATE_HZ,
    STRUT_COUNT,
    STRUT_LABEL,
    InvalidStrutMessage,
    StrutSample,
    parse_layout_labels,
    sample_sim_time,
)

VERIFIED_RCLPY_VERSION = "7.1.6"
"""The rclpy release whose private APIs this module was verified against."""

PUBLIC_API_ENV = "HEXAPOD_RCLPY_PUBLIC_API"
"""Environment variable: set to 1 to use only rclpy's public API."""

_RCLPY_DISTRIBUTIONS = ("ros-jazzy-rclpy", "ros-rclpy")
"""PyPI distributions of rclpy (the README's set-up); apt installs have the ament index."""

try:
    from rclpy._rclpy_pybind11 import RCLError
except ImportError:             # pragma: no cover - another rclpy layout
    RCLError = RuntimeError     # what it derives from

RCL_ERRORS = (RuntimeError, InvalidHandle)
"""What an rcl call on a destroyed entity or a shut-down context raises (RCLError included)."""


def parameter_overrides(node: Any) -> dict[str, Any]:
    """The parameter values given to ``node`` at start-up (``-p``, params files), by name.

    rclpy keeps them in the private ``Node._parameter_overrides`` (verified with 7.1.6);
    without it, an empty mapping: unknown parameters then go unreported.
    """
    return dict(getattr(node, "_parameter_overrides", {}))


# ---------------------------------------------------------------------------- version check
def rclpy_version() -> str | None:
    """The installed rclpy's version (PyPI distribution or ament index), None if unknown."""
    for name in _RCLPY_DISTRIBUTIONS:
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    try:
        from ament_index_python.packages import get_package_share_directory

        xml = Path(get_package_share_directory("rclpy"), "package.xml").read_text()
    except Exception:           # noqa: BLE001 - no ament index, no rclpy share: unknown
        return None
    match = re.search(r"<version>\s*([^<\s]+)\s*</version>", xml)
    return match.group(1) if match else None


def _missing_api() -> str:
    """The first private API this module needs that rclpy lacks ("" if none)."""
    try:
        from rclpy.impl.implementation_singleton import rclpy_implementation as impl
    except ImportError:
        return "rclpy.impl.implementation_singleton"
    needed = {"WaitSet": ("clear_entities", "add_subscription", "wait", "get_ready_entities"),
              "Subscription": ("take_message",), "Publisher": ("publish_raw",)}
    for cls, methods in needed.items():
        for method in methods:
            if not hasattr(getattr(impl, cls, None), method):
                return f"{cls}.{method}"
    return "" if RCLError is not RuntimeError else "_rclpy_pybind11.RCLError"


@functools.cache
def fast_path_problem() -> str:
    """Why the private fast path is not used ("" when it is)."""
    if os.environ.get(PUBLIC_API_ENV, "") not in ("", "0"):
        return f"{PUBLIC_API_ENV} is set"
    version = rclpy_version()
    if version != VERIFIED_RCLPY_VERSION:
        return f"rclpy {version or '(unknown version)'} is not {VERIFIED_RCLPY_VERSION}"
    missing = _missing_api()
    return f"rclpy lacks {missing}" if missing else ""


@functools.cache
def fast_path() -> bool:
    """Whether the private fast path is used; logs once why not."""
    problem = fast_path_problem()
    if problem:
        rclpy.logging.get_logger("hexapod_vibration").warning(
            f"{problem}: using rclpy's public API for the loop (slower, same results)")
    return not problem


# ---------------------------------------------------------------------------- private API
class LoopWaitSet:
    """A persistent rcl wait set over a node's loop subscriptions (fast path only)."""

    def __init__(self, context: Any, subscriptions: Sequence[Any]) -> None:
        """Allocate the wait set for ``subscriptions`` in ``context`` (an rclpy Context)."""
        from rclpy.impl.implementation_singleton import rclpy_implementation as impl

        self.subscriptions = list(subscriptions)
        self._handles = [sub.handle for sub in self.subscriptions]
        self._by_pointer = {sub.handle.pointer: sub for sub in self.subscriptions}
        self._wait_set = impl.WaitSet(len(self.subscriptions), 0, 0, 0, 0, 0, context.handle)

    def wait(self, timeout_s: float) -> list[Any]:
        """The subscriptions with data, waiting up to ``timeout_s`` (0: a poll) for one.

        Data queued before the call counts: rcl returns at once then.
        """
        wait_set = self._wait_set
        wait_set.clear_entities()
        for handle in self._handles:
            wait_set.add_subscription(handle)
        wait_set.wait(int(timeout_s * 1e9))
        by_pointer = self._by_pointer
        return [by_pointer[p] for p in wait_set.get_ready_entities("subscription")]


def take_serialized(subscription: Any) -> bytes | None:
    """One queued message of ``subscription`` as CDR bytes, None if none (fast path only).

    Without rclpy's destruction guard (``with subscription.handle``): the loop that takes
    runs in the node's thread, which destroys the node only after the loop ended.
    """
    taken = subscription.handle.take_message(subscription.msg_type, True)
    return None if taken is None else taken[0]


def take_serialized_batch(subscription: Any, limit: int) -> list[bytes]:
    """Up to ``limit`` queued messages as CDR bytes; [] on the public path (executor's job)."""
    if not fast_path():
        return []
    taken = []
    with subscription.handle:
        for _ in range(limit):
            item = subscription.handle.take_message(subscription.msg_type, True)
            if item is None:
                break
            taken.append(item[0])
    return taken


def serialized_publish(publisher: Any) -> Callable[[bytes], None]:
    """A function publishing CDR bytes on ``publisher`` (an rclpy Publisher).

    rclpy's ``Publisher.publish(bytes)`` is ``handle.publish_raw`` behind a type check and a
    destruction guard (~3 us); the fast path calls it directly (the node outlives its loop).
    """
    return publisher.handle.publish_raw if fast_path() else publisher.publish


# ---------------------------------------------------------------------------- CDR
_CDR_LE = b"\x00\x01"          # encapsulation: plain CDR (XCDR1), little endian
_CDR_BE = b"\x00\x00"          # plain CDR (XCDR1), big endian
_CDR_HEADER = 4                # encapsulation bytes; alignment counts from after them
MAX_LAYOUT_DIMS = 16
"""More ``layout.dim`` entries than this is an impossible layout for a loop message."""
_U32 = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}
_LE32 = _U32["<"]


def _string(text: bytes) -> bytes:
    """CDR string at a 4-aligned position: length (NUL included), bytes, NUL, padding."""
    return _LE32.pack(len(text) + 1) + text + bytes(1 + (-(len(text) + 1) % 4))


_ONE_ONE = struct.pack("<II", 1, 1)            # size and stride of dim[1] and dim[2]
_PREFIX = {dims: _CDR_LE + b"\x00\x00" + _LE32.pack(dims) + _string(STRUT_LABEL.encode())
           + _LE32.pack(STRUT_COUNT) + _LE32.pack(STRUT_COUNT) for dims in (2, 3)}
"""Encapsulation, dims count, dim[0] = ("strut", 6, 6): the same for every loop message."""
_DATA_HEADER = struct.pack("<II", 0, STRUT_COUNT)   # data_offset, length of data
_SAMPLE_FORMAT = SAMPLE_LABEL_PREFIX.encode() + b"%d"
_RUN_FORMAT = RUN_LABEL_PREFIX.encode() + b"%d"


def encode_strut_cdr(values: np.ndarray | Sequence[float], sample_index: int,
                     run: int | None = None) -> bytes:
    """The serialized (little-endian CDR) form of ``make_strut_array(values, index, run)``.

    About 2.5 us here, against about 15 us for building the message and serializing it.

    Raises:
        ValueError: ``values`` does not hold exactly six numbers, ``sample_index`` < 0 or
            ``run`` < 1.
    """
    flat = np.asarray(values, dtype="<f8")
    if flat.size != STRUT_COUNT:
        raise ValueError(f"expected {STRUT_COUNT} strut values, got {flat.size}")
    if sample_index < 0:
        raise ValueError(f"sample index must be >= 0, got {sample_index}")
    if run is not None and run < 1:
        raise ValueError(f"run id must be >= 1, got {run}")
    if not fast_path():
        return _public_strut_bytes(flat, sample_index, run)
    parts = [_PREFIX[2 if run is None else 3], _string(_SAMPLE_FORMAT % sample_index), _ONE_ONE]
    if run is not None:
        parts += [_string(_RUN_FORMAT % run), _ONE_ONE]
    parts.append(_DATA_HEADER)
    head = b"".join(parts)
    return b"".join((head, bytes(-(len(head) - _CDR_HEADER) % 8), flat.tobytes()))


def _public_strut_bytes(values: np.ndarray, sample_index: int, run: int | None) -> bytes:
    """:func:`encode_strut_cdr` through rclpy's public serializer."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    labels = [(STRUT_LABEL, STRUT_COUNT), (f"{SAMPLE_LABEL_PREFIX}{sample_index}", 1)]
    if run is not None:
        labels.append((f"{RUN_LABEL_PREFIX}{run}", 1))
    msg = Float64MultiArray(data=values.tolist())
    msg.layout.dim = [MultiArrayDimension(label=label, size=n, stride=n) for label, n in labels]
    return serialize_message(msg)


class UnsupportedCdr(InvalidStrutMessage):
    """Bytes that are not a Float64MultiArray in plain CDR: truncated, garbage, other encoding."""


def decode_strut_cdr(raw: bytes, count: int = STRUT_COUNT) -> StrutSample:
    """The six values, sample index and run of a serialized ``/pph/*`` message.

    ``count``: the number of values the topic carries (6 on the strut topics; 1 on
    ``/pph/reference_frequency``).

    Reads plain CDR (XCDR1) in either byte order without building the Python message
    (about 3 us against about 19 us for rclpy's conversion), with the rules of
    ``messages.parse_strut_array``, and refuses anything that is not exactly one
    well-formed ``Float64MultiArray``: every length is checked against the bytes, at most
    :data:`MAX_LAYOUT_DIMS` dims, and the data must end the message.

    Raises:
        UnsupportedCdr: Another encapsulation, truncated or trailing bytes, an impossible
            layout or a label that is not UTF-8.
        InvalidStrutMessage: Not six values, a non-finite value, a bad sample or run label.
    """
    order = {_CDR_LE: "<", _CDR_BE: ">"}.get(bytes(raw[:2]))
    if order is None or len(raw) < _CDR_HEADER + 12:
        raise UnsupportedCdr(f"not a plain CDR Float64MultiArray ({len(raw)} bytes, "
                             f"encapsulation {bytes(raw[:2]).hex()})")
    try:
        pos, labels = _read_layout(raw, _U32[order])
        (received,) = _U32[order].unpack_from(raw, pos)
    except (struct.error, UnicodeDecodeError) as exc:
        raise UnsupportedCdr(f"malformed Float64MultiArray CDR: {exc}") from None
    if received != count:
        kind = "strut values" if count == STRUT_COUNT else "value(s)"
        raise InvalidStrutMessage(f"expected {count} {kind}, got {received}")
    pos += 4
    pos += -(pos - _CDR_HEADER) % 8                        # float64 alignment
    if not 0 <= len(raw) - (pos + 8 * count) <= 3:
        raise UnsupportedCdr(f"malformed Float64MultiArray CDR: {len(raw)} bytes for "
                             f"{pos + 8 * count}")
    values = np.frombuffer(raw, dtype=order + "f8", count=count, offset=pos)
    if order == ">":
        values = values.astype(np.float64)
        values.flags.writeable = False
    if not all(map(math.isfinite, values.tolist())):
        raise InvalidStrutMessage(f"non-finite strut value in {values.tolist()}")
    index, run = parse_layout_labels(labels)
    return StrutSample(values, index, run)


def _read_layout(raw: bytes, u32: struct.Struct) -> tuple[int, list[str]]:
    """Walk ``layout`` (dims, data_offset): the offset of ``data`` and the labels kept.

    Labels after dim[2] and dim[0]'s are not decoded (nothing reads them): "" stands in.
    """
    (dims,) = u32.unpack_from(raw, _CDR_HEADER)
    if dims > MAX_LAYOUT_DIMS:
        raise UnsupportedCdr(f"impossible layout: {dims} dims")
    pos, labels = _CDR_HEADER + 4, []
    for d in range(dims):
        (length,) = u32.unpack_from(raw, pos)              # string length incl. NUL
        end = pos + 4 + length
        if length < 1 or end > len(raw) or raw[end - 1] != 0:
            raise UnsupportedCdr(f"bad string of length {length} in layout.dim[{d}]")
        labels.append(bytes(raw[pos + 4:end - 1]).decode() if d in (1, 2) else "")
        pos = end + (-(end - _CDR_HEADER) % 4) + 8          # align, then size and stride
    return pos + 4, labels                                   # data_offset (uint32)


_CLOCK_CDR = struct.Struct("<4siI")     # encapsulation (LE CDR), sec (int32), nanosec


def clock_cdr(sample: int, sample_rate_hz: float = SAMPLE_RATE_HZ) -> bytes:
    """``rosgraph_msgs/Clock`` at the sim time of loop sample ``sample`` as CDR bytes.

    What rclpy serializes from ``Clock(clock=sample_time(sample))`` (tested), built without
    the Python message: the driver publishes it every sample.
    """
    sec, nanosec = sample_sim_time(sample, sample_rate_hz)
    if not fast_path():
        from builtin_interfaces.msg import Time
        from rclpy.serialization import serialize_message
        from rosgraph_msgs.msg import Clock

        return serialize_message(Clock(clock=Time(sec=sec, nanosec=nanosec)))
    return _CLOCK_CDR.pack(b"\x00\x01\x00\x00", sec, nanosec)
