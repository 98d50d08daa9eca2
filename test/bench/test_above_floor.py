"""The nodes' own work: the graph's budget minus the message path's, from one bench's results."""

import pytest

from hexapod_vibration.bench.above_floor import above_floor_markdown, cpu_above_floor, window_rate


def _budget(driver_us: float = 380.0) -> dict:
    cpu = {node: {"process": us, "main thread": us / 2} for node, us in
           (("pph_driver", driver_us), ("notch_controller", 267.0),
            ("pointing_controller", 200.0), ("pph_recorder", 160.0))}
    return {"processes/lockstep/recorder": {"cpu_us_per_sample": cpu, "samples": 44000,
                                            "wall_s": 30.0},
            "composed/lockstep/recorder": {"cpu_us_per_sample": {}, "samples": 80000,
                                           "wall_s": 30.0}}


FLOOR = {"lockstep/recorder": {"cpu_us_per_sample": {"driver": 319.0, "notch": 164.0,
                                                     "pointing": 164.0, "recorder": 104.0},
                               "x_real_time": 2.0},
         "lockstep/recorder/composed": {"cpu_us_per_sample": {}, "x_real_time": 4.0}}


def test_each_process_above_its_message_path():
    rows = cpu_above_floor(_budget(), FLOOR)
    assert rows["driver"] == {"graph": 380.0, "floor": 319.0, "above": 61.0}
    assert rows["notch"]["above"] == pytest.approx(103.0)
    assert cpu_above_floor(_budget(), {}) == {} and cpu_above_floor({}, FLOOR) == {}


def test_the_table_and_the_rates_against_the_floor():
    table = above_floor_markdown(_budget(), FLOOR)
    assert "| driver | 380 | 319 | 61 |" in table
    assert "| total | 1007 | 751 | 256 |" in table
    assert "through processes, with the recorder: the graph 1.47x" in table
    assert ": 0.73 of its rate." in table                 # 44 000 samples in 30 s / 2.00x
    assert "composed, with the recorder: the graph 2.67x" in table
    assert ": 0.67 of its rate." in table
    assert window_rate({"samples": 3000, "wall_s": 2.0}) == pytest.approx(1.5)
    assert window_rate({"failed": "no driver"}) is None
    assert above_floor_markdown({"processes/lockstep/recorder": {"failed": "x"}}, FLOOR) == ""
