"""The message-path floor: its processes (or the composed one) run the loop's exchange.

The numbers are make bench's; here the floor must run, pair every command with its sample and
measure a window of samples in each process (every sample accounted for).
"""

from __future__ import annotations

import pytest

from hexapod_vibration.bench.floor_nodes import ROLES, CpuWindow
from hexapod_vibration.bench.message_floor import floor_markdown, floor_summary, run_floor


def test_the_cpu_window_opens_at_the_warmup_and_ignores_repeats():
    window = CpuWindow(warmup=10)
    assert window.result() == {"samples": 0, "cpu_s": 0.0, "wall_s": 0.0}
    for sample in (3, 10, 11, 11, 9, 25):
        window.saw(sample)
    result = window.result()
    assert result["samples"] == 15 and result["cpu_s"] >= 0.0 and result["wall_s"] > 0.0


def test_summary_divides_each_window_and_formats_the_table():
    measured = {role: {"samples": 1000, "cpu_s": 0.1, "wall_s": 0.5} for role in ROLES}
    measured["driver"]["late"] = 5
    summary = floor_summary(measured, "realtime")
    assert summary["cpu_us_per_sample"]["notch"] == pytest.approx(100.0)
    assert summary["total_us"] == pytest.approx(400.0)
    assert summary["x_real_time"] == pytest.approx(2.0)
    assert summary["late_fraction"] == pytest.approx(0.005)
    table = floor_markdown({"realtime": summary, "lockstep": {"failed": "no driver"}})
    assert "| realtime | 100 | 100 | 100 | 100 | 400 | 2.00 | 0.500 | - / - |" in table
    assert "failed: no driver" in table


@pytest.mark.parametrize("composed", [False, True], ids=["processes", "composed"])
def test_the_floor_runs_its_processes_in_lockstep(ros_env, tmp_path, composed):
    result = run_floor(tmp_path, "lockstep", samples=1500, warmup=300, env=ros_env,
                       timeout_s=240.0, composed=composed)
    assert result["samples"] == 1500 - 1 - 300       # window: sample 300 to the last, 1499
    processes = {"driver", "recorder"} if composed else set(ROLES)
    assert set(result["cpu_us_per_sample"]) == processes
    assert all(us > 0.0 for us in result["cpu_us_per_sample"].values())
    assert result["x_real_time"] > 0.0 and "late_fraction" not in result
    assert 0.0 < result["latency_ms_p50"] <= result["latency_ms_p99"]
    table = floor_markdown({"lockstep/recorder/composed": result})
    assert ("(one process) | - | - |" in table) is composed
