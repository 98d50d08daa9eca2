"""Design-space sweeps of the core closed loop on Dask (``sweep`` console script).

- :mod:`~hexapod_vibration.sweep.grid`: the grid YAML (a base scenario, dotted paths and
  the values to sweep), validated before any work; one :class:`~.grid.PointSpec` per point.
- a point's control-on and windows against the notch's identification: a grid that
  overlaps it is refused (:mod:`~hexapod_vibration.core.sim.timeline`, which ``experiment``
  uses too).
- :mod:`~hexapod_vibration.sweep.outcome`: what control did in a point's run (its status).
- :mod:`~hexapod_vibration.sweep.point`: one point on the core loop (no ROS) and its
  metrics, from the report's own level, reduction and convergence code.
- :mod:`~hexapod_vibration.sweep.loop_model`: the LTI plant the canceller sees (linear PPH,
  pointing loop closed), for the exact stability bound.
- :mod:`~hexapod_vibration.sweep.bounds`: the bounds of mu of a point (identified, model).
- :mod:`~hexapod_vibration.sweep.results`: per-point result files, resume, Parquet table.
- :mod:`~hexapod_vibration.sweep.maps`: heat maps, statuses hatched, bounds overlaid.
- :mod:`~hexapod_vibration.sweep.runner`: serial or Dask execution with a progress bar.
"""
