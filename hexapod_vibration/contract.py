"""ROS-free description of the ``/pph/*`` array layout, shared by messages.py and bag_io.py.

``layout.dim[0] = ("strut", 6, 6)``; the driver and controllers add
``layout.dim[1] = ("sample:<n>", 1, 1)`` carrying the loop's sample index ``n`` in band.
This module has no ROS import so that bag analysis runs without rclpy.
"""

from __future__ import annotations

STRUT_COUNT = 6
"""Number of struts, hence of values in every ``/pph/*`` message."""

SAMPLE_RATE_HZ = 1000.0
"""Loop rate (Hz): sample n is at n / SAMPLE_RATE_HZ s of sim time."""

STRUT_LABEL = 'strut'
"""Label of ``layout.dim[0]``."""

SAMPLE_LABEL_PREFIX = 'sample:'
"""Prefix of the label of ``layout.dim[1]``, followed by the decimal sample index."""


class InvalidStrutMessage(ValueError):
    """A ``/pph/*`` message that cannot be used: wrong length, non-finite or bad label."""


def sample_label(sample_index: int) -> str:
    """Label ``sample:<n>`` of ``layout.dim[1]`` for sample index ``n`` (>= 0).

    Raises:
        ValueError: ``sample_index`` is negative.
    """
    if sample_index < 0:
        raise ValueError(f'sample index must be >= 0, got {sample_index}')
    return f'{SAMPLE_LABEL_PREFIX}{int(sample_index)}'


def parse_sample_label(label: str) -> int:
    """Parse ``sample:<n>`` (n: ASCII decimal digits) into ``n``.

    Raises:
        InvalidStrutMessage: Any other label.
    """
    if not label.startswith(SAMPLE_LABEL_PREFIX):
        raise InvalidStrutMessage(
            f'layout.dim[1] label {label!r} is not {SAMPLE_LABEL_PREFIX!r}<sample index>'
        )
    digits = label[len(SAMPLE_LABEL_PREFIX) :]
    if not (digits.isascii() and digits.isdigit()):
        raise InvalidStrutMessage(
            f'garbled sample label {label!r}: expected {SAMPLE_LABEL_PREFIX!r} followed by '
            'a non-negative decimal integer'
        )
    return int(digits)
