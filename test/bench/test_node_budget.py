"""The CPU budget's arithmetic and tables (the measurement itself is make bench's)."""

from __future__ import annotations

import os

import pytest

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
