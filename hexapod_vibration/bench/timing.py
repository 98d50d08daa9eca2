"""Timing of controller steps, timeit-style, round-robin so that load changes hit all alike.

``repeat`` rounds of ``number`` calls of ``step(error, out)`` each (garbage collector off);
the result is the median (and the minimum) over the rounds of the mean time per call, in
microseconds per sample. Timings are machine- and load-dependent: they belong in the
benchmark's output, never in pass/fail tests.
"""

from __future__ import annotations

import dataclasses
import gc
import time
from collections.abc import Callable

import numpy as np


@dataclasses.dataclass(frozen=True)
class TimingSettings:
    """Calls per run (``number``) and runs (``repeat``) of each timing; warm-up calls."""

    number: int
    repeat: int
    warmup: int = 200


QUICK_TIMING = TimingSettings(number=300, repeat=3, warmup=50)
FULL_TIMING = TimingSettings(number=2000, repeat=15, warmup=500)


Step = Callable[[np.ndarray, np.ndarray], np.ndarray]


def time_steps_us(steps: dict[str, tuple[Step, int]], timing: TimingSettings,
                  seed: int = 0) -> dict[str, dict[str, float]]:
    """Per-call time (us) of each ``step(error, out)``, measured round-robin.

    Every round times each configuration once (``timing.number`` calls, garbage collector
    off), so a change of machine load during the benchmark affects all configurations
    alike; the result per configuration is the median (and the minimum) over the
    ``timing.repeat`` rounds of the mean time per call. The errors cycle through 1024
    pre-drawn random vectors (0.01 m/s^2 RMS) so that the controllers adapt on changing
    data, without denormals or allocation in the loop.

    Args:
        steps: name -> (bound ``step`` method, number of error channels).
        timing: calls per run, rounds, warm-up calls.
        seed: seed of the error vectors.

    Returns:
        name -> {"median": us, "min": us}.
    """
    rng = np.random.default_rng(seed)
    runners = {}
    for name, (step, n_channels) in steps.items():
        errors = 0.01 * rng.standard_normal((1024, n_channels))
        out = np.zeros(n_channels)
        for k in range(timing.warmup):
            step(errors[k & 1023], out)
        runners[name] = _step_runner(step, errors, out, timing.number)
    return round_robin_us(runners, timing.number, timing.repeat)


def _step_runner(step: Step, errors: np.ndarray, out: np.ndarray,
                 number: int) -> Callable[[], None]:
    """A call of ``number`` steps on the cycled ``errors`` (what one round times)."""
    def run() -> None:
        for k in range(number):
            step(errors[k & 1023], out)

    return run


def round_robin_us(runners: dict[str, Callable[[], None]], samples_per_run: int,
                    repeat: int) -> dict[str, dict[str, float]]:
    """Median and minimum time per sample (us) of each runner over ``repeat`` rounds.

    Each round calls every runner once (garbage collector off), so a change of machine
    load affects all of them alike.
    """
    runs: dict[str, list[float]] = {name: [] for name in runners}
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(repeat):
            for name, run in runners.items():
                t0 = time.perf_counter_ns()
                run()
                runs[name].append((time.perf_counter_ns() - t0) / samples_per_run / 1e3)
    finally:
        if was_enabled:
            gc.enable()
    return {name: {"median": float(np.median(r)), "min": float(np.min(r))}
            for name, r in runs.items()}
