"""Where a sweep keeps its results: one file per point, and the table of them all.

``DIR/points/<point_id>.json`` is written (atomically: a temporary file renamed) as soon as
a point is done, whether it succeeded or failed, so an interrupted sweep loses at most the
points that were running. A point whose file exists is done: a resumed sweep skips it
(``--retry-failed`` runs the points whose status is ``failed`` again). The id is a digest
of the point's complete scenario and model, so a changed base scenario or model never
reuses an old result.

``DIR/results.parquet`` is the table (pyarrow): one row per point of the grid in grid
order, one column per swept path (named by the path), the point's seed, ``status`` and
``error``, and every metric of :mod:`hexapod_vibration.sweep.point` (lists as list
columns). Parquet keeps the types (floats, bools, nulls and lists), which CSV would turn
into strings, and is read by pandas, polars, DuckDB or pyarrow alike.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from hexapod_vibration.sweep.grid import Grid, PointSpec
from hexapod_vibration.sweep.outcome import FAILED

POINTS_DIR = "points"
TABLE_NAME = "results.parquet"
LEADING = ("index", "point_id", "status", "error", "seed")


def point_file(out_dir: Path, point_id: str) -> Path:
    """The result file of one point."""
    return out_dir / POINTS_DIR / f"{point_id}.json"


def write_point(out_dir: Path, spec: PointSpec, row: dict[str, Any]) -> Path:
    """Write a point's row (with its assignments) atomically; the file's path."""
    path = point_file(out_dir, spec.point_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {"assignments": spec.assignments, "row": row}
    fd, tmp = tempfile.mkstemp(prefix=f".{spec.point_id}.", dir=path.parent)
    with os.fdopen(fd, "w", encoding="utf-8") as stream:
        json.dump(_jsonable(data), stream, indent=1, allow_nan=False)
        stream.write("\n")
    os.replace(tmp, path)
    return path


def read_point(out_dir: Path, point_id: str) -> dict[str, Any] | None:
    """A point's stored row, or None if it has none (or an unreadable one)."""
    try:
        with open(point_file(out_dir, point_id), encoding="utf-8") as stream:
            return json.load(stream)["row"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def pending_points(grid: Grid, out_dir: Path, retry_failed: bool = False) -> list[PointSpec]:
    """The grid's points without a result in ``out_dir`` (and the failed ones if asked)."""
    pending = []
    for spec in grid.points:
        row = read_point(out_dir, spec.point_id)
        if row is None or (retry_failed and row.get("status") == FAILED):
            pending.append(spec)
    return pending


def collect_rows(grid: Grid, out_dir: Path) -> list[dict[str, Any]]:
    """The table's rows: the grid's points that have a result, in grid order."""
    rows = []
    for spec in grid.points:
        row = read_point(out_dir, spec.point_id)
        if row is None:
            continue
        rows.append({**{k: row.get(k) for k in LEADING},
                     **{p: spec.assignments.get(p) for p in grid.swept_paths},
                     "seed": spec.assignments["seed"],
                     **{k: v for k, v in row.items() if k not in LEADING}})
    return rows


def write_table(rows: list[dict[str, Any]], path: Path) -> Path:
    """Write the rows as Parquet (columns in first-seen order, missing values null)."""
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns]
    table = pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in rows])
    tmp = path.with_name(f".{path.name}.tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path


def read_table(path: Path) -> list[dict[str, Any]]:
    """A results table as a list of rows (dicts)."""
    return pq.read_table(path).to_pylist()


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "item"):            # numpy scalars
        return _jsonable(value.item())
    return value
