"""A realtime driver's late commands from a given sample on (its own counts, /diagnostics).

The driver reports, about once a second, its ``sample``, the ``samples`` it stepped and its
``late_commands`` (samples whose command was not back by their deadline; counted by
``core/loop/command_arbiter``). :func:`late_since` counts from its first report at or after a
sample S (``from_sample``) to its last report: nothing before S counts (a late command
between S and that report, at most one report period, is not counted either: the count
starts at ``from_sample``, said with it). ``make bench`` follows live reports the same way
(``bench/late_window.py``), S being where the notch's identification was over. No ROS
import.
"""

from __future__ import annotations

from collections.abc import Sequence


def driver_counts(status: dict[str, str]) -> tuple[int, int, int]:
    """(sample, samples stepped, late commands) of one driver report (-1, 0, 0 if empty)."""
    return (int(status.get("sample", -1)), int(float(status.get("samples", 0) or 0)),
            int(float(status.get("late_commands", 0) or 0)))


def late_since(reports: Sequence[dict[str, str]], first_sample: int
               ) -> tuple[int, int, int] | None:
    """(from_sample, samples, late commands) from ``first_sample`` on.

    From the first report at or after ``first_sample`` (its sample: ``from_sample``) to the
    last report; None if no report is at or after it.
    """
    counts = [driver_counts(r) for r in reports]
    start = next((c for c in counts if c[0] >= first_sample), None)
    if start is None:
        return None
    _, samples, late = counts[-1]
    return start[0], samples - start[1], late - start[2]
