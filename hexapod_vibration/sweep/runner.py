"""Run a grid's pending points, serially or on a Dask cluster, and write the outputs.

Dask (``dask.distributed``) does all the distribution: :func:`local_client` starts a
``LocalCluster`` of single-threaded worker processes on this machine (every usable core by
default); :func:`remote_client` connects to an existing scheduler (``dask scheduler`` and
``dask worker`` started by the user) and changes nothing on it. Each point is one task
(:func:`~hexapod_vibration.sweep.point.run_point`); results are written as they arrive, in
any order, so the table does not depend on which worker ran what.
"""

from __future__ import annotations

import logging
import os
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hexapod_vibration.sweep import results
from hexapod_vibration.sweep.grid import Grid, PointSpec
from hexapod_vibration.sweep.outcome import FAILED, STATUSES
from hexapod_vibration.sweep.point import failed_row, run_point

CONNECT_TIMEOUT_S = 10.0
PROGRESS_LOG_INTERVAL_S = 10.0
_ENVIRON_BEFORE: dict[int, dict[str, str]] = {}   # os.environ before a local cluster, by id(client)


@dataclass
class SweepSummary:
    """What a sweep did: points run now, skipped (already done), their statuses; outputs."""

    total: int
    computed: int
    skipped: int
    statuses: dict[str, int]
    wall_s: float
    table: Path | None = None
    figures: list[Path] = field(default_factory=list)

    @property
    def failed(self) -> int:
        """Points that raised (status ``failed``)."""
        return self.statuses.get(FAILED, 0)

    def line(self) -> str:
        """One line for the console."""
        counts = ", ".join(f"{n} {status}" for status in STATUSES
                           if (n := self.statuses.get(status, 0)))
        return (f"{self.total} points: {self.computed} run now, {self.skipped} already done; "
                f"{counts or 'none done'}; {self.wall_s:.1f} s")


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def local_client(workers: int | None = None) -> Any:
    """A Dask client on a new LocalCluster: ``workers`` processes of one thread each."""
    from dask.distributed import Client, LocalCluster

    n = workers or usable_cores()
    environ = dict(os.environ)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    _ENVIRON_BEFORE[id(client)] = environ
    _restore_environ(environ)
    return client


def _restore_environ(environ: dict[str, str]) -> None:
    """Put ``os.environ`` back as it was before a local cluster started.

    Dask's nanny writes its workers' settings (``MALLOC_TRIM_THRESHOLD_``,
    ``OMP_NUM_THREADS=1``, ``PYTHONHASHSEED``...) into the parent's environment before it
    spawns a worker; every process started later (a benchmark's ROS nodes) inherits them.
    """
    for key in set(os.environ) - set(environ):
        del os.environ[key]
    os.environ.update(environ)


def remote_client(address: str) -> Any:
    """A Dask client on the scheduler at ``address`` (e.g. ``tcp://host:8786``)."""
    from dask.distributed import Client

    return Client(address, timeout=CONNECT_TIMEOUT_S)


def close_client(client: Any) -> None:
    """Close a client and, if it started one, its local cluster."""
    cluster = getattr(client, "cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()
    environ = _ENVIRON_BEFORE.pop(id(client), None)
    if environ is not None:
        _restore_environ(environ)


def _serial(points: list[PointSpec]) -> Iterator[tuple[PointSpec, dict[str, Any]]]:
    for spec in points:
        yield spec, run_point(spec)


def run_on_dask(client: Any, points: list[PointSpec]
                ) -> Iterator[tuple[PointSpec, dict[str, Any]]]:
    """Run the points on the client's cluster; (spec, row) pairs as they finish."""
    from dask.distributed import as_completed

    token = uuid.uuid4().hex[:8]
    futures = {}
    for spec in points:
        future = client.submit(run_point, spec, key=f"sweep-point-{spec.point_id}-{token}",
                               pure=False)
        futures[future.key] = (future, spec)
    try:
        for future in as_completed([f for f, _ in futures.values()]):
            spec = futures[future.key][1]
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - e.g. a worker that died: recorded
                row = failed_row(spec, exc)
            future.release()
            yield spec, row
    finally:
        for future, _ in futures.values():
            future.cancel()


class _Lines:
    """A stream for tqdm that writes each refresh as a line (a log, not a terminal)."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> None:
        """One line per refresh; tqdm's carriage returns dropped."""
        text = text.replace("\r", "").strip()
        if text:
            self._stream.write(text + "\n")

    def flush(self) -> None:
        """Flush the underlying stream."""
        self._stream.flush()


def _progress(total: int, enabled: bool) -> Any:
    """A tqdm bar on stderr: redrawn in a terminal, a line every 10 s in a log."""
    from tqdm import tqdm

    terminal = sys.stderr.isatty()
    return tqdm(total=total, unit="point", desc="sweep", disable=not enabled,
                dynamic_ncols=terminal, ncols=None if terminal else 80,
                file=sys.stderr if terminal else _Lines(sys.stderr),
                mininterval=0.1 if terminal else PROGRESS_LOG_INTERVAL_S)


def run_sweep(grid: Grid, out_dir: Path, client: Any = None, retry_failed: bool = False,
              progress: bool = True, plots: bool = True,
              on_point: Callable[[PointSpec, dict[str, Any]], None] | None = None
              ) -> SweepSummary:
    """Run the grid's pending points (serially when ``client`` is None) and write outputs.

    Writes ``out_dir/points/*.json`` as points finish, then ``out_dir/results.parquet``
    and, if ``plots``, the maps. Points already done are skipped. Interrupted (Ctrl-C),
    the points finished so far stay written.
    """
    start = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "grid.yaml").write_text(grid.source.read_text(encoding="utf-8"),
                                       encoding="utf-8")
    pending = results.pending_points(grid, out_dir, retry_failed)
    stream = _serial(pending) if client is None else run_on_dask(client, pending)
    bar = _progress(len(pending), progress)
    try:
        for spec, row in stream:
            results.write_point(out_dir, spec, row)
            if on_point is not None:
                on_point(spec, row)
            bar.update(1)
    finally:
        bar.close()
    rows = results.collect_rows(grid, out_dir)
    statuses: dict[str, int] = {}
    for row in rows:
        statuses[row["status"]] = statuses.get(row["status"], 0) + 1
    summary = SweepSummary(total=len(grid.points), computed=len(pending),
                           skipped=len(grid.points) - len(pending), statuses=statuses,
                           wall_s=time.perf_counter() - start)
    summary.table = results.write_table(rows, out_dir / results.TABLE_NAME)
    if plots:
        from hexapod_vibration.sweep import maps

        summary.figures = maps.write_maps(grid, rows, out_dir)
    summary.wall_s = time.perf_counter() - start
    return summary
