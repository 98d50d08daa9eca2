"""Conversion between ``std_msgs/Float64MultiArray`` and per-strut values with a sample index.

Every ``/pph/*`` topic carries six values in strut order 1..6 (SI units: m/s^2, m or N) with
``layout.dim[0] = ("strut", 6, 6)``. The driver and the controllers add
``layout.dim[1] = ("sample:<n>", 1, 1)``: the array keeps its 6 values (shape (6, 1)) and
carries the loop's sample index ``n`` in band, so commands pair with samples exactly and the
analysis places every value on its sample whatever the transport jitter.

Both functions run once per message at 1 kHz, so they avoid per-element Python work and
copies: the values go into the message as one ``array.array('d')`` built from the numpy
buffer, and come out as a read-only numpy view on the received message's buffer.
Measured on this project's 2-core machine: about 6 us to make, 2.5 us to parse.
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from hexapod_vibration.strut_layout import (
    SAMPLE_LABEL_PREFIX,
    STRUT_COUNT,
    STRUT_LABEL,
    InvalidStrutMessage,
    parse_sample_label,
    sample_label,
)

__all__ = [
    'SAMPLE_LABEL_PREFIX',
    'STRUT_COUNT',
    'STRUT_LABEL',
    'InvalidStrutMessage',
    'StrutArrayPublisher',
    'make_strut_array',
    'parse_strut_array',
    'receive_strut_array',
]

_FLOAT64 = np.dtype(np.float64)


def make_strut_array(
    values: np.ndarray | Sequence[float], sample_index: int | None
) -> Float64MultiArray:
    """Build a ``/pph/*`` message from six per-strut values.

    Args:
        values: Six values in strut order 1..6, SI units of the topic (m/s^2, m or N).
        sample_index: Loop sample index ``n`` (>= 0) the values belong to, carried in
            ``layout.dim[1]``; ``None`` leaves it out (shape (6,), as other publishers do).

    Returns:
        The message, ready to publish.

    Raises:
        ValueError: ``values`` does not hold exactly six numbers or ``sample_index`` < 0.
    """
    flat = np.ascontiguousarray(values, dtype=_FLOAT64).reshape(-1)
    if flat.shape[0] != STRUT_COUNT:
        raise ValueError(f'expected {STRUT_COUNT} strut values, got {flat.shape[0]}')
    dims = [MultiArrayDimension(label=STRUT_LABEL, size=STRUT_COUNT, stride=STRUT_COUNT)]
    if sample_index is not None:
        dims.append(MultiArrayDimension(label=sample_label(sample_index), size=1, stride=1))
    msg = Float64MultiArray()
    msg.layout.dim = dims
    msg.data = array.array('d', flat.tobytes())
    return msg


class StrutArrayPublisher:
    """Publish ``/pph/*`` messages at 1 kHz from one reused message (no per-sample allocation).

    rclpy converts the message to its C form inside ``publish``, so the Python message can
    be overwritten for the next sample as soon as ``publish`` returns. Measured on the
    project's 2-core machine (no subscriber): 8.1 us per publish against 15.0 us for
    :func:`make_strut_array` + publish.
    """

    def __init__(self, publisher: Any) -> None:
        """Wrap an rclpy publisher of ``std_msgs/Float64MultiArray``."""
        self.publisher = publisher
        self._msg = make_strut_array(np.zeros(STRUT_COUNT), 0)
        self._values = np.frombuffer(self._msg.data, dtype=_FLOAT64)
        self._sample_dim = self._msg.layout.dim[1]

    def publish(self, values: np.ndarray | Sequence[float], sample_index: int) -> None:
        """Publish six values (SI units of the topic) for loop sample ``sample_index`` >= 0.

        Raises:
            ValueError: ``values`` does not hold exactly six numbers or the index is < 0.
        """
        self._values[:] = values
        self._sample_dim.label = sample_label(sample_index)
        self.publisher.publish(self._msg)


def parse_strut_array(msg: Float64MultiArray) -> tuple[np.ndarray, int | None]:
    """Extract the six values and the in-band sample index of a ``/pph/*`` message.

    ``layout.dim[0]`` is not checked: a publisher that sends six values without a layout
    (e.g. ``ros2 topic pub``) is accepted, without a sample index.

    Args:
        msg: A received (or locally built) ``std_msgs/Float64MultiArray``.

    Returns:
        ``(values, sample_index)``: ``values`` is a read-only float64 view of shape (6,)
        on the message's buffer (copy it if the message is mutated afterwards),
        ``sample_index`` the index from ``layout.dim[1]``, or ``None`` when the publisher
        did not send one.

    Raises:
        InvalidStrutMessage: Not six values, a value is NaN or infinite, or
            ``layout.dim[1]`` is present but not a well-formed ``sample:<n>`` label.
    """
    data = msg.data
    if len(data) != STRUT_COUNT:
        raise InvalidStrutMessage(f'expected {STRUT_COUNT} strut values, got {len(data)}')
    if not all(map(math.isfinite, data)):
        raise InvalidStrutMessage(f'non-finite strut value in {list(data)}')
    if isinstance(data, array.array):
        values = np.frombuffer(data, dtype=_FLOAT64)
    else:
        values = np.asarray(data, dtype=_FLOAT64)
    values.flags.writeable = False
    dims = msg.layout.dim
    if len(dims) < 2:
        return values, None
    return values, parse_sample_label(dims[1].label)


def receive_strut_array(msg: Float64MultiArray, logger: Any, topic: str
                        ) -> tuple[np.ndarray, int | None] | None:
    """:func:`parse_strut_array` for a subscription callback: ``None`` for a bad message.

    The reason is logged as a warning, throttled by rclpy to once a second per process
    (the throttle is keyed by this call site); the caller counts every rejection.
    """
    try:
        return parse_strut_array(msg)
    except InvalidStrutMessage as exc:
        logger.warn(f'{topic}: rejected message ({exc})', throttle_duration_sec=1.0)
        return None
