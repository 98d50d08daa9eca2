"""The numbers of report.json and details.json: 6 decimals, NaN written as null."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hexapod_vibration.json_values import json_float, jsonable
from hexapod_vibration.json_values import write_json as write_json_values

REPORT_DIGITS = 6
"""Decimals of the numbers in report.json and details.json."""


def report_float(value: float) -> float | None:
    """``value`` rounded to :data:`REPORT_DIGITS` decimals; None for NaN or infinity."""
    return json_float(value, REPORT_DIGITS)


def report_jsonable(value: Any) -> Any:
    """``value`` (NumPy arrays and scalars too) as JSON values, floats as :func:`report_float`."""
    return jsonable(value, REPORT_DIGITS)


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON (NaN written as null), numbers to 6 decimals, atomically."""
    write_json_values(path, data, REPORT_DIGITS)
