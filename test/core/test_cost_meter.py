"""LoopCostMeter: CPU per sample by stage, thread and process, from the clocks it is given."""

from __future__ import annotations

import pytest

from hexapod_vibration.core.loop.cost_meter import (
    STAGE_STRIDE_SAMPLES,
    WINDOW_SAMPLES,
    LoopCostMeter,
)


class FakeClock:
    def __init__(self):
        self.t = 0.0
        self.reads = 0

    def __call__(self) -> float:
        self.reads += 1
        return self.t


def test_laps_charge_each_stage_and_a_window_closes_every_window_samples():
    thread, process = FakeClock(), FakeClock()
    meter = LoopCostMeter(thread, process)
    wait, work = meter.stage("wait"), meter.stage("work")
    assert meter.stage("wait") == wait                     # registered once
    for _ in range(WINDOW_SAMPLES):
        thread.t += 30e-6
        meter.lap(wait)
        thread.t += 70e-6
        meter.lap(work)
        process.t += 150e-6                                # 50 us in other threads
        assert meter.last_window() == {}                   # not closed before the end
        meter.count()
    window = meter.last_window()
    assert window["wait"] == pytest.approx(30.0)
    assert window["work"] == pytest.approx(70.0)
    assert window["main thread"] == pytest.approx(100.0)
    assert window["process"] == pytest.approx(150.0)
    assert window["other threads"] == pytest.approx(50.0)
    assert meter.report()["cpu_us_per_sample work"] == pytest.approx(70.0)
    for _ in range(WINDOW_SAMPLES):                        # the next window stands alone
        thread.t += 10e-6
        meter.lap(work)
        process.t += 10e-6
        meter.count()
    assert meter.last_window()["work"] == pytest.approx(10.0)
    assert meter.last_window()["wait"] == pytest.approx(0.0)


def test_a_stage_registered_in_the_middle_of_a_window_counts_from_then():
    thread, process = FakeClock(), FakeClock()
    meter = LoopCostMeter(thread, process, stride_samples=1)     # every sample timed
    first = meter.stage("first")
    for k in range(WINDOW_SAMPLES):
        if k == WINDOW_SAMPLES // 2:
            late = meter.stage("late")
        thread.t += 1e-6
        meter.lap(first if k < WINDOW_SAMPLES // 2 else late)
        meter.count()
    assert meter.last_window()["first"] == pytest.approx(0.5)
    assert meter.last_window()["late"] == pytest.approx(0.5)


def test_only_the_first_owner_counts_the_samples_of_a_process():
    meter = LoopCostMeter(FakeClock(), FakeClock())
    driver, notch = meter.counter("pph_driver"), meter.counter("notch_controller")
    assert meter.counter("pph_driver") == meter.count      # the same owner again
    driver()
    notch()
    notch()
    assert meter.samples == 1


def test_stages_are_timed_on_one_sample_in_the_stride_the_thread_and_process_on_all():
    """A stage's figure is its mean over the timed samples; laps between cost no clock read."""
    thread, process = FakeClock(), FakeClock()
    meter = LoopCostMeter(thread, process)
    wait, work = meter.stage("wait"), meter.stage("work")
    reads_before = thread.reads
    for k in range(WINDOW_SAMPLES):
        thread.t += 5e-6
        meter.lap(wait)
        thread.t += 10e-6 if k % 10 == 0 else 1e-6       # periodic work every 10 samples
        meter.lap(work)
        process.t += 30e-6
        meter.count()
    window = meter.last_window()
    assert window["main thread"] == pytest.approx(5.0 + 1.9)   # exact: 1.9 us mean work
    assert window["process"] == pytest.approx(30.0)
    assert window["wait"] == pytest.approx(5.0)
    assert window["work"] == pytest.approx(1.9, rel=0.05)       # 143 timed samples
    timed = -(-WINDOW_SAMPLES // STAGE_STRIDE_SAMPLES)
    assert thread.reads - reads_before <= 3 * timed + 1         # 2 laps + 1 restart, a close


@pytest.mark.parametrize("stride", [0, -1])
def test_a_stride_below_one_sample_is_refused(stride):
    with pytest.raises(ValueError, match="stride_samples"):
        LoopCostMeter(FakeClock(), FakeClock(), stride_samples=stride)
