"""The machine's 1 kHz wake-ups: the summary's arithmetic, and real sleepers measured.

The numbers are make bench's; here the fractions must be those of the lateness given, and a
short run of real processes must account for every wake-up.
"""

from __future__ import annotations

import numpy as np
import pytest

from hexapod_vibration.bench.ros_bench import ros_summary_markdown
from hexapod_vibration.bench.wakeup_lateness import (
    LATE_MS,
    measure_wakeups,
    sleep_lateness,
    wakeup_markdown,
    wakeup_summary,
)


def test_summary_counts_wakeups_later_than_each_threshold():
    one = np.array([0.0, 1.5, 2.5, 3.5]) * 1e-3             # s
    two = np.array([0.1, 0.1, 0.1, 4.0, 9.0]) * 1e-3         # longer: its tail not compared
    summary = wakeup_summary([one, two])
    assert LATE_MS == (1.0, 2.0, 3.0)
    assert summary["processes"] == 2 and summary["wakeups"] == 9
    assert summary["late_fraction"] == pytest.approx({"1": 5 / 9, "2": 4 / 9, "3": 3 / 9})
    # deadlines 0..3: one late at 1, 2, 3 (> 1 ms), two at 3 (> 1, 2, 3 ms)
    assert summary["any_late_fraction"] == pytest.approx({"1": 3 / 4, "2": 2 / 4, "3": 1 / 4})
    assert summary["max_ms"] == pytest.approx(9.0)
    table = wakeup_markdown({"two": summary, "fifo": {"refused": "the OS refused"}})
    assert "| two | 9 | 55.556 | 44.444 | 33.333 | 25.000 |" in table
    assert "| fifo | the OS refused |" in table
    section = ros_summary_markdown({"wakeups": {"two": summary}})
    assert "### The machine's 1 kHz wake-ups" in section
    assert wakeup_markdown({"two": summary}) in section


def test_a_sleeper_wakes_at_or_after_each_deadline():
    late = sleep_lateness(50, period_s=2e-3)
    assert late.shape == (50,) and np.all(late >= 0.0)


def test_sleeper_processes_report_every_wakeup():
    summary = measure_wakeups(processes=2, seconds=0.2)
    assert summary["processes"] == 2 and summary["wakeups"] == 400
    fractions = [summary["late_fraction"][f"{t:g}"] for t in LATE_MS]
    assert all(0.0 <= f <= 1.0 for f in fractions) and fractions == sorted(fractions)[::-1]
