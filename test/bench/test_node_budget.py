"""The CPU budget's arithmetic and tables (the measurement itself is make bench's)."""

from __future__ import annotations

import os

import pytest

from hexapod_vibration.bench.late_window import LateWindow
from hexapod_vibration.bench.node_budget import (
    BUDGET_SETUPS,
    budget_summary_markdown,
    cpu_per_sample,
    process_cpu_s,
    stage_costs,
    stages_markdown,
)


def test_cpu_per_sample_divides_the_window_by_its_samples():
    before = {"pph_driver": (10.0, 8.0), "notch_controller": (5.0, 4.0)}
    after = {"pph_driver": (10.4, 8.3), "notch_controller": (5.2, 4.1)}
    cpu = cpu_per_sample(before, after, 1000)
    assert cpu["pph_driver"]["process"] == pytest.approx(400.0)
    assert cpu["pph_driver"]["main thread"] == pytest.approx(300.0)
    assert cpu["notch_controller"]["process"] == pytest.approx(200.0)


def test_process_cpu_reads_this_process():
    total, main = process_cpu_s(os.getpid())
    assert total >= main >= 0.0


def test_stage_costs_and_tables():
    statuses = {"pph_driver": {"cpu_us_per_sample driver plant": "84.5", "sample": "9000",
                               "cpu_us_per_sample process": "400.0"}}
    stages = stage_costs(statuses)
    assert stages == {"pph_driver": {"driver plant": 84.5, "process": 400.0}}
    key = BUDGET_SETUPS[1].key
    budget = {key: {"cpu_us_per_sample": {"pph_driver": {"process": 400.0},
                                          "notch_controller": {"process": 300.0},
                                          "pointing_controller": {"process": 200.0},
                                          "pph_recorder": {"process": 100.0}},
                    "stages": stages, "loop": {"missed_fraction": 0.0005,
                                               "latency_ms_p99": "0.8"}}}
    table = budget_summary_markdown(budget).splitlines()
    assert table[2] == f"| {key} | 400 | 300 | 200 | 100 | 1000 | 0.050 | 0.8 |"
    assert "| pph_driver | process | 400.0 |" in stages_markdown(budget, key)


class _Monitor:
    """What LateWindow reads of a GraphMonitor: the latest status values of each node."""

    def __init__(self):
        self.driver: dict[str, str] = {}
        self.notch: dict[str, str] = {}

    def report(self, sample: int, late: int, state: str | None = None,
               notch_sample: int = 0) -> None:
        self.driver = {"sample": str(sample), "samples": str(sample), "late_commands": str(late)}
        if state is not None:
            self.notch = {"state": state, "last_sample": str(notch_sample)}


def test_the_late_window_starts_at_the_first_driver_report_after_the_notch_settled():
    watch = _Monitor()
    window = LateWindow(watch)
    watch.report(5000, 3, "identifying", 4990)
    assert not window.follow() and window.counts() == (0, 0)
    watch.report(11000, 10, "identifying", 11500)
    assert not window.follow()
    watch.report(12000, 800, "adapting", 12100)      # the analysis: 790 late
    assert not window.follow()                      # this report is older than the notch's
    watch.report(13000, 805)
    assert window.follow() and window.settled
    watch.report(43000, 835)
    assert window.counts() == (30000, 30)
    assert window.report() == {"control_samples": 30000, "control_late": 30,
                               "control_missed_fraction": 0.001, "control_settled": True}


def test_a_late_window_started_by_hand_says_the_notch_had_not_settled():
    watch = _Monitor()
    window = LateWindow(watch)
    watch.report(3000, 4, "identifying", 2990)
    assert window.start_now() == (3000, 4)
    watch.report(7000, 6)
    assert window.report()["control_late"] == 2 and not window.report()["control_settled"]
    watch.report(9000, 6, "refused", 8950)          # refusal also ends the start
    assert window.follow()                          # started already (by hand)
    assert not window.settled
