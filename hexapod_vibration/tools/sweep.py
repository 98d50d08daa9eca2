"""``sweep GRID.yaml --out DIR``: run a design-space grid of the core closed loop on Dask.

Every point of the grid (see :mod:`hexapod_vibration.sweep.grid`) is one run of the core
closed loop (no ROS); its metrics go to ``DIR/points/``, the table to
``DIR/results.parquet`` and the heat maps to ``DIR/*.png``. By default the points run on
a Dask ``LocalCluster`` using every core of this machine; ``--scheduler tcp://HOST:8786``
sends them to an existing Dask cluster (``dask scheduler`` / ``dask worker``; the workers
need this package installed). Points already in DIR are skipped, so an interrupted sweep
resumes where it stopped. A point that fails is recorded with its error; the sweep goes on.

A grid whose control-on or analysis windows fall inside the notch's identification is
refused before anything runs (:mod:`hexapod_vibration.core.sim.timeline`). Each point's
``status`` says what control did (``ok``, ``clamped``, ``backed_off``, ``faded``,
``refused``, or ``failed`` with its error); the summary line counts them. A progress bar
runs on stderr while the points complete (one line every 10 s when stderr is a file).

Exit status: 0 when the sweep ran (even if some points failed: see the summary and the
``status`` column), 2 for a bad grid or argument (one line on stderr, nothing run or
written), 130 on Ctrl-C (the finished points are kept).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from hexapod_vibration.paths import share_directory

PROG = "sweep"


def _parser() -> argparse.ArgumentParser:
    shipped = share_directory() / "config" / "sweeps"
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Run a grid of core closed-loop simulations on Dask and write a Parquet "
                    "table and heat maps of attenuation and of the largest rise, with the "
                    "bounds of mu overlaid.",
        epilog=f"Shipped grids: {shipped}/*.yaml (a grid may also be given by name, e.g. "
               "'mu_bound').")
    parser.add_argument("grid", help="grid YAML file, or the name of a shipped grid")
    parser.add_argument("--out", required=True, type=Path, help="output folder (resumable)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="address of an existing Dask scheduler, e.g. tcp://host:8786")
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local cluster (default: every core)")
    where.add_argument("--serial", action="store_true",
                       help="run the points one by one in this process (no Dask)")
    parser.add_argument("--retry-failed", action="store_true",
                        help="run again the points recorded as failed")
    parser.add_argument("--no-plots", action="store_true", help="write the table only")
    parser.add_argument("--dry-run", action="store_true",
                        help="validate the grid and list how many points would run")
    return parser


def _grid_path(text: str) -> Path:
    path = Path(text)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return path
    return share_directory() / "config" / "sweeps" / f"{text}.yaml"


def main(argv: Sequence[str] | None = None) -> int:
    """Console script; see the module docstring."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error(f"--workers must be >= 1, got {args.workers}")
    if args.out.exists() and not args.out.is_dir():
        parser.error(f"--out {args.out} exists and is not a folder")
    from hexapod_vibration.sweep.grid import GridError, load_grid  # numpy: after --help

    try:
        grid = load_grid(_grid_path(args.grid))
    except GridError as exc:
        parser.exit(2, f"{PROG}: error: {exc}\n")
    from hexapod_vibration.sweep import results, runner

    pending = results.pending_points(grid, args.out, args.retry_failed)
    print(f"{grid.name}: {len(grid.points)} points, {len(pending)} to run "
          f"({len(grid.points) - len(pending)} already in {args.out})", flush=True)
    if args.dry_run:
        return 0
    client = None
    try:
        if pending and not args.serial:
            client = _client(parser, args)
        summary = runner.run_sweep(grid, args.out, client, args.retry_failed,
                                   plots=not args.no_plots)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; finished points are kept in {args.out}", file=sys.stderr)
        return 130
    finally:
        if client is not None:
            runner.close_client(client)
    print(summary.line())
    print(f"table: {summary.table}")
    for figure in summary.figures:
        print(f"figure: {figure}")
    return 0


def _client(parser: argparse.ArgumentParser, args: argparse.Namespace):
    """The Dask client: an existing scheduler, or a new local cluster."""
    from hexapod_vibration.sweep import runner

    if args.scheduler:
        try:
            return runner.remote_client(args.scheduler)
        except (OSError, TimeoutError, ValueError) as exc:
            text = " ".join(str(exc).split()) or type(exc).__name__
            parser.exit(2, f"{PROG}: error: cannot reach the Dask scheduler at "
                           f"{args.scheduler}: {text}\n")
    client = runner.local_client(args.workers)
    workers = len(client.scheduler_info()["workers"])
    print(f"local Dask cluster: {workers} workers x 1 thread", flush=True)
    return client


if __name__ == "__main__":
    sys.exit(main())
