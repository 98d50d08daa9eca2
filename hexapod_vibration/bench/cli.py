"""Command line of ``hexapod_bench``: checked before the benchmark's heavy imports."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from hexapod_vibration import cli


def build_parser() -> argparse.ArgumentParser:
    """``hexapod_bench --out DIR [--quick] [--skip-sweep] [--skip-ros]``."""
    parser = cli.ArgumentParser(
        prog="hexapod_bench",
        description="Per-sample cost of the notch vs filtered-x LMS, scaling, and both "
                    "controllers on the Table 1 scenario; writes results.json and summary.md.")
    parser.add_argument("--out", required=True, type=cli.output_dir, help="output folder")
    parser.add_argument("--quick", action="store_true",
                        help="short timings and a shortened scenario (smoke test)")
    parser.add_argument("--skip-sweep", action="store_true",
                        help="leave out the sweep throughput (points/s with 1 and 2 workers)")
    parser.add_argument("--skip-ros", action="store_true",
                        help="leave out the ROS loop benchmark (realtime, lockstep_speedup)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse and check the arguments, then run the benchmarks."""
    args = build_parser().parse_args(argv)
    from hexapod_vibration.bench.core_bench import run

    return run(args)
