"""Heat maps of a sweep: attenuation and the largest rise over two axes, bounds overlaid.

One PNG per grid (``DIR/<name>_maps.png``; several when there are many facets): a row per
combination of the axes that are not on the map (e.g. ``notch.adaptation``), two panels
per row:

- attenuation (dB): the smallest reduction of the lines the notch aims at;
- largest rise elsewhere (dB, ``max_rise_vs_off_db``: against the same run without
  control, same window and noise): red where control made a band or a line worse, the
  +1 dB of "never worse than off" marked.

A cell shows the point's value only where control ran at the requested setting
(status ``ok``, :mod:`hexapod_vibration.sweep.outcome`). Hatched cells did not: a
``clamped`` or ``backed_off`` point keeps its colour and value (measured, at the lower
rate the supervisor ran) under a hatch with its status; a ``faded``, ``refused`` or
``failed`` point is grey with its status (its reason is in the table). A thick black frame
marks a point whose loop diverged (:mod:`hexapod_vibration.sweep.point`: past the
actuator rating, or a rise of more than 20 dB). When the map's y axis is ``notch.mu``, the
bounds of mu of each column are drawn over it (:mod:`hexapod_vibration.sweep.bounds`):
the bound the supervisor identified and enforces (a mu at or above it is clamped), and the
loop's stability limit on the linear plant's model with the update as it ran. A bound
beyond the map's range is drawn at its edge with an arrow and its value.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import colors, patches  # noqa: E402
from matplotlib import patheffects as effects  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from hexapod_vibration.contract import NEVER_WORSE_DB  # noqa: E402
from hexapod_vibration.sweep.grid import Axis, Grid  # noqa: E402
from hexapod_vibration.sweep.outcome import NOT_CONTROLLED, OK  # noqa: E402

DPI = 150
MU_PATH = "notch.mu"
RISE_SCALE_MAX_DB = 20.0        # colour scale of the rise; larger values keep their number
FACETS_PER_FIGURE = 4
ANNOTATE_MAX_CELLS = 15          # per axis: more cells than this are left unlabelled
BOUND_STYLES = {                 # column -> (legend, line style, colour)
    "mu_bound_identified": ("identified bound ({methods}): a mu at or above it is clamped "
                            "to half", "--", "darkorange"),
    "mu_bound_model": ("stability limit, linear plant model, the update as it ran", "-",
                       "black"),
    "mu_limit_sensitivity": ("predicted-sensitivity limit", ":", "magenta"),
}
HATCH = "////"
STATUS_TEXT = {"clamped": "clamped", "backed_off": "backed off", "faded": "faded",
               "refused": "refused", "failed": "failed"}
OUTLINE = [effects.withStroke(linewidth=3.6, foreground="white")]
OUTLINE_THIN = [effects.withStroke(linewidth=2.0, foreground="0.85")]
PANELS = (("attenuation_db", "attenuation of the targeted lines (dB)", "viridis"),
          ("max_rise_vs_off_db", "largest rise elsewhere vs control off (dB; scale line: +1)",
           "RdBu_r"))


def write_maps(grid: Grid, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
    """Draw the grid's maps into ``out_dir``; the PNGs written (none without two axes)."""
    x_axis, y_axis = _map_axes(grid)
    if x_axis is None or y_axis is None:
        return []
    others = [a for a in grid.axes if a.path not in (x_axis.path, y_axis.path)]
    facets = list(itertools.product(*(a.values for a in others))) or [()]
    groups = [facets[i:i + FACETS_PER_FIGURE] for i in range(0, len(facets),
                                                            FACETS_PER_FIGURE)]
    paths = []
    for number, group in enumerate(groups):
        suffix = "" if len(groups) == 1 else f"_{number + 1}"
        path = out_dir / f"{grid.name}_maps{suffix}.png"
        _figure(grid, rows, x_axis, y_axis, others, group, path)
        paths.append(path)
    return paths


def _map_axes(grid: Grid) -> tuple[Axis | None, Axis | None]:
    """The grid's plot axes, else its last two axes (y the last, mu preferred)."""
    if "x" in grid.plot and "y" in grid.plot:
        return grid.axis(grid.plot["x"]), grid.axis(grid.plot["y"])
    if len(grid.axes) < 2:
        return None, None
    y = grid.axis(MU_PATH) or grid.axes[-1]
    x = next(a for a in reversed(grid.axes) if a is not y)
    return x, y


def _same(a: Any, b: Any) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isclose(a, b))


def _cells(rows: list[dict], x: Axis, y: Axis, fixed: dict[str, Any]) -> list[list[dict]]:
    """rows[j][i]: the row at y value j and x value i of this facet (or {})."""
    table = [[{} for _ in x.values] for _ in y.values]
    for row in rows:
        if not all(_same(row.get(p), v) for p, v in fixed.items()):
            continue
        i = next((k for k, v in enumerate(x.values) if _same(row.get(x.path), v)), None)
        j = next((k for k, v in enumerate(y.values) if _same(row.get(y.path), v)), None)
        if i is not None and j is not None:
            table[j][i] = row
    return table


def _figure(grid: Grid, rows: list[dict], x: Axis, y: Axis, others: list[Axis],
            facets: list[tuple], path: Path) -> None:
    width = max(5.5, 0.75 * len(x.values) + 2.5)
    height = max(3.8, 0.42 * len(y.values) + 1.9)
    fig, axes = plt.subplots(len(facets), 2, figsize=(2 * width, height * len(facets)),
                             squeeze=False, constrained_layout=True)
    for r, facet in enumerate(facets):
        fixed = {a.path: v for a, v in zip(others, facet, strict=True)}
        cells = _cells(rows, x, y, fixed)
        where = ", ".join(f"{a.title} = {_tick(v)}" for a, v in zip(others, facet, strict=True))
        for c, (column, title, cmap) in enumerate(PANELS):
            ax = axes[r][c]
            _panel(ax, cells, x, y, column, cmap)
            ax.set_title(f"{title}" + (f"\n{where}" if where else ""), fontsize=10)
            if y.path == MU_PATH:
                _bounds(ax, cells, y)
    handles = _legend_handles(rows, y)
    fig.suptitle(f"{grid.name}: {grid.description}".strip(": "), fontsize=11)
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=min(2, len(handles)),
                   fontsize=8, frameon=False)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _values(cells: list[list[dict]], column: str) -> np.ndarray:
    """The column's values; NaN where the point has none or control did not run."""
    return np.array([[np.nan if row.get(column) is None or not _measured(row)
                      else float(row[column]) for row in line] for line in cells])


def _measured(row: dict) -> bool:
    """Control ran in the controlled window (at the requested rate or a lower one)."""
    return bool(row) and row.get("status") not in NOT_CONTROLLED


def _panel(ax: Any, cells: list[list[dict]], x: Axis, y: Axis, column: str, cmap: str) -> None:
    data = _values(cells, column)
    finite = data[np.isfinite(data)]
    if column == "max_rise_vs_off_db":
        top = min(max(float(finite.max()) if finite.size else 1.0, 2.0 * NEVER_WORSE_DB),
                  RISE_SCALE_MAX_DB)
        low = max(min(float(finite.min()) if finite.size else -1.0, -NEVER_WORSE_DB),
                  -RISE_SCALE_MAX_DB)
        norm = colors.TwoSlopeNorm(vcenter=0.0, vmin=low, vmax=top)
    else:
        norm = colors.Normalize(vmin=min(0.0, float(finite.min())) if finite.size else 0.0,
                                vmax=float(finite.max()) if finite.size else 1.0)
    mesh = ax.pcolormesh(np.ma.masked_invalid(data), cmap=cmap, norm=norm, shading="flat")
    extend = "neither"
    if finite.size and column == "max_rise_vs_off_db":
        extend = {(False, False): "neither", (True, False): "min", (False, True): "max",
                  (True, True): "both"}[(bool(finite.min() < norm.vmin),
                                         bool(finite.max() > norm.vmax))]
    bar = plt.colorbar(mesh, ax=ax, pad=0.01, extend=extend)
    bar.ax.tick_params(labelsize=7)
    if column == "max_rise_vs_off_db":
        bar.ax.axhline(NEVER_WORSE_DB, color="black", linewidth=1.5)
    annotate = len(x.values) <= ANNOTATE_MAX_CELLS and len(y.values) <= ANNOTATE_MAX_CELLS
    for j, line in enumerate(cells):
        for i, row in enumerate(line):
            _cell(ax, i, j, row, data[j, i], mesh, annotate)
    ax.set_xticks(np.arange(len(x.values)) + 0.5, [_tick(v) for v in x.values], fontsize=8)
    ax.set_yticks(np.arange(len(y.values)) + 0.5, [_tick(v) for v in y.values], fontsize=8)
    ax.set_xlim(0, len(x.values))
    ax.set_ylim(0, len(y.values))
    ax.set_xlabel(x.title, fontsize=9)
    ax.set_ylabel(y.title, fontsize=9)


def _cell(ax: Any, i: int, j: int, row: dict, value: float, mesh: Any, annotate: bool) -> None:
    status = row.get("status") if row else None
    if not _measured(row):
        ax.add_patch(patches.Rectangle((i, j), 1, 1, facecolor="0.85", edgecolor="0.5",
                                       hatch=HATCH, linewidth=0.5))
        if annotate and status:
            ax.text(i + 0.5, j + 0.5, STATUS_TEXT.get(status, status), ha="center",
                    va="center", fontsize=6, color="0.15", path_effects=OUTLINE_THIN)
        return
    if status != OK:
        ax.add_patch(patches.Rectangle((i, j), 1, 1, fill=False, edgecolor="0.25",
                                       hatch=HATCH, linewidth=0.0, alpha=0.6))
    if row.get("diverged"):
        ax.add_patch(patches.Rectangle((i + 0.04, j + 0.04), 0.92, 0.92, fill=False,
                                       edgecolor="black", linewidth=2.0))
    if not (annotate and math.isfinite(value)):
        return
    rgba = mesh.cmap(mesh.norm(value))
    light = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] > 0.55
    text = f"{value:.1f}" if abs(value) < 9.95 else f"{value:.0f}"
    if status != OK:
        text += f"\n{STATUS_TEXT.get(status, status)}"
    ax.text(i + 0.5, j + 0.5, text, ha="center", va="center", fontsize=7 if status == OK
            else 6, color="black" if light else "white", zorder=5, path_effects=[
                effects.withStroke(linewidth=2.0, foreground="white" if light else "black")])


def _tick(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _y_position(y: Axis, value: float) -> float:
    """Where ``value`` falls on the y axis (cell j spans [j, j+1]), extrapolated."""
    v = np.array([float(t) for t in y.values])
    u = float(value)
    if y.scale == "log":
        v, u = np.log10(v), math.log10(u) if u > 0 else -math.inf
    centres = np.arange(len(v)) + 0.5
    if not math.isfinite(u):
        return -math.inf
    order = np.argsort(v)
    v, centres = v[order], centres[order]
    if len(v) == 1:
        return float(centres[0])
    if u <= v[0]:
        return float(centres[0] + (u - v[0]) / (v[1] - v[0]) * (centres[1] - centres[0]))
    if u >= v[-1]:
        return float(centres[-1] + (u - v[-1]) / (v[-1] - v[-2]) * (centres[-1] - centres[-2]))
    return float(np.interp(u, v, centres))


def _column_bound(line_cells: list[dict], column: str) -> float | None:
    values = [float(r[column]) for r in line_cells if r and r.get(column) is not None]
    return float(np.median(values)) if values else None


def _bounds(ax: Any, cells: list[list[dict]], y: Axis) -> None:
    """Each column's bounds as a staircase over the map."""
    top = len(y.values)
    for order, (column, (_, style, colour)) in enumerate(BOUND_STYLES.items()):
        inset = 0.2 + 0.25 * order            # labels of bounds off the map, stacked
        xs, ys = [], []
        for i in range(len(cells[0])):
            bound = _column_bound([line[i] for line in cells], column)
            if bound is None:
                xs += [np.nan]
                ys += [np.nan]
                continue
            pos = _y_position(y, bound)
            clipped = min(max(pos, 0.0), float(top))
            if clipped != pos:
                arrow = "\u2191" if clipped == top else "\u2193"
                ax.text(i + 0.5, clipped - inset if clipped == top else clipped + inset,
                        f"{arrow} {bound:.2g}", ha="center", va="center", fontsize=7,
                        color=colour, fontweight="bold", path_effects=OUTLINE)
            xs += [i, i + 1, np.nan]
            ys += [clipped, clipped, np.nan]
        ax.plot(xs, ys, linestyle=style, color=colour, linewidth=2.2, path_effects=OUTLINE)


def _legend_handles(rows: list[dict], y: Axis) -> list[Any]:
    handles: list[Any] = []
    if y.path == MU_PATH:
        methods = sorted({str(r["mu_bound_method"]) for r in rows
                          if r.get("mu_bound_method")})
        for column, (label, style, colour) in BOUND_STYLES.items():
            if any(r.get(column) is not None for r in rows):
                handles.append(Line2D([], [], linestyle=style, color=colour, linewidth=2.2,
                                      label=label.format(methods=" / ".join(methods)),
                                      path_effects=OUTLINE))
    handles.append(patches.Patch(facecolor="none", edgecolor="black", linewidth=2.0,
                                 label="diverged (past the actuator rating, or a rise > 20 dB)"))
    handles.append(patches.Patch(facecolor="white", edgecolor="0.25", hatch=HATCH,
                                 label="clamped / backed off: measured at the lower mu the "
                                       "supervisor ran"))
    handles.append(patches.Patch(facecolor="0.85", edgecolor="0.5", hatch=HATCH,
                                 label="faded / refused / failed: no control to measure "
                                       "(reason: the table's control_note, error)"))
    return handles
