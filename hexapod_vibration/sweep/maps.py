"""Heat maps of a sweep: attenuation and the largest rise over two axes, bounds overlaid.

One PNG per grid (``DIR/<name>_maps.png``; several when there are many facets): a row per
combination of the axes that are not on the map (e.g. ``notch.adaptation``), two panels
per row:

- attenuation (dB): the smallest reduction of the lines the notch aims at;
- largest rise elsewhere (dB, ``max_rise_vs_off_db``: against the same run without
  control, same window and noise): red where control made a band or a line worse, the
  +1 dB of "never worse than off" marked.

Every cell shows its value; a thick black frame marks a point whose loop diverged
(:mod:`hexapod_vibration.sweep.point`: past the actuator rating, or a rise of more than
20 dB), a grey hatched cell a point that failed or was refused (its
error is in the table). When the map's y axis is ``notch.mu``, the predicted bounds of mu
of each column are drawn over it: eq. 18 averaged (identified G), the exact LTI bound
(linear plant's model) and, once it exists, the predicted-sensitivity limit. A bound beyond
the map's range is drawn at its edge with an arrow and its value.
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

from hexapod_vibration.contract import NEVER_WORSE_DB
from hexapod_vibration.sweep.grid import Axis, Grid  # noqa: E402

DPI = 150
MU_PATH = "notch.mu"
RISE_SCALE_MAX_DB = 20.0        # colour scale of the rise; larger values keep their number
FACETS_PER_FIGURE = 4
ANNOTATE_MAX_CELLS = 15          # per axis: more cells than this are left unlabelled
BOUND_STYLES = {                 # column -> (legend, line style, colour)
    "mu_bound_eq18": ("eq. 18 averaged bound (identified G)", "--", "darkorange"),
    "mu_bound_exact_lti": ("exact LTI bound (linear plant model)", "-", "black"),
    "mu_limit_sensitivity": ("predicted-sensitivity limit", ":", "magenta"),
}
OUTLINE = [effects.withStroke(linewidth=3.6, foreground="white")]
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
        fig.legend(handles=handles, loc="outside lower center", ncol=min(3, len(handles)),
                   fontsize=8, frameon=False)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _values(cells: list[list[dict]], column: str) -> np.ndarray:
    return np.array([[np.nan if row.get(column) is None else float(row[column])
                      for row in line] for line in cells])


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
    if not row or row.get("status") != "ok":
        ax.add_patch(patches.Rectangle((i, j), 1, 1, facecolor="0.85", edgecolor="0.5",
                                       hatch="///", linewidth=0.5))
        if annotate and row:
            ax.text(i + 0.5, j + 0.5, "refused" if "stability bound" in (row.get("error")
                                                                       or "") else "failed",
                    ha="center", va="center", fontsize=6, color="0.2")
        return
    if row.get("diverged"):
        ax.add_patch(patches.Rectangle((i + 0.04, j + 0.04), 0.92, 0.92, fill=False,
                                       edgecolor="black", linewidth=2.0))
    if annotate and math.isfinite(value):
        rgba = mesh.cmap(mesh.norm(value))
        light = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] > 0.55
        text = f"{value:.1f}" if abs(value) < 9.95 else f"{value:.0f}"
        ax.text(i + 0.5, j + 0.5, text, ha="center", va="center", fontsize=7,
                color="black" if light else "white", zorder=5, path_effects=[
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
    """Each column's predicted bounds as a staircase over the map."""
    top = len(y.values)
    for column, (_, style, colour) in BOUND_STYLES.items():
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
                ax.text(i + 0.5, clipped - 0.2 if clipped == top else clipped + 0.2,
                        f"{arrow} {bound:.2g}", ha="center", va="center", fontsize=7,
                        color=colour, fontweight="bold", path_effects=OUTLINE)
            xs += [i, i + 1, np.nan]
            ys += [clipped, clipped, np.nan]
        ax.plot(xs, ys, linestyle=style, color=colour, linewidth=2.2, path_effects=OUTLINE)


def _legend_handles(rows: list[dict], y: Axis) -> list[Any]:
    handles: list[Any] = []
    if y.path == MU_PATH:
        for column, (label, style, colour) in BOUND_STYLES.items():
            if any(r.get(column) is not None for r in rows):
                handles.append(Line2D([], [], linestyle=style, color=colour, linewidth=2.2,
                                      label=label, path_effects=OUTLINE))
    handles.append(patches.Patch(facecolor="none", edgecolor="black", linewidth=2.0,
                                 label="diverged (past the actuator rating, or a rise > 20 dB)"))
    handles.append(patches.Patch(facecolor="0.85", edgecolor="0.5", hatch="///",
                                 label="refused or failed (see the table's error)"))
    return handles
