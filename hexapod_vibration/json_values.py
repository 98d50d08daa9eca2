"""Python and NumPy values to JSON (report.json, details.json, bench/results.json), no ROS.

NaN and infinities, which JSON cannot hold, are written as ``null``; NumPy scalars and
arrays become Python numbers and lists; keys become strings.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np


def json_float(value: float, digits: int | None = None) -> float | None:
    """``value`` as a JSON number (rounded to ``digits`` decimals if given), None if not finite."""
    value = float(value)
    if not math.isfinite(value):
        return None
    return value if digits is None else round(value, digits)


def jsonable(value: Any, digits: int | None = None) -> Any:
    """``value`` with every dict, sequence, array and number made JSON-ready (recursively)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [jsonable(v, digits) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return json_float(value, digits)
    return value


def write_json(path: Path, data: Any, digits: int | None = None) -> None:
    """Write ``data`` as indented JSON (:func:`jsonable`), with a final newline.

    Atomically (:func:`hexapod_vibration.tools.outputs.write_text`): the file is complete or
    absent, never half written.
    """
    from hexapod_vibration.tools.outputs import write_text

    write_text(Path(path), json.dumps(jsonable(data, digits), indent=2) + "\n")
