"""Both controllers compiled (numba): their arithmetic cost per sample, and their equivalence."""

from __future__ import annotations

import functools
import time
from typing import Any, Protocol

import numpy as np

from hexapod_vibration.baseline.fxlms import DEFAULT_CONTROL_TAPS, DEFAULT_PATH_TAPS
from hexapod_vibration.bench.controllers import STRUTS, make_fxlms, make_notch, tone_frequencies
from hexapod_vibration.bench.costs import (
    FXLMS_PATH_TAPS,
    FXLMS_SAME_TONES,
    NOTCH_TONES,
    RATIO_NOTCH_TONES,
)
from hexapod_vibration.bench.timing import TimingSettings, round_robin_us

COMPILED_NOTCH_TONES = NOTCH_TONES
COMPILED_FXLMS_PATH_TAPS = FXLMS_PATH_TAPS
# samples compared between the compiled kernels and the numpy controllers
EQUIVALENCE_SAMPLES = 3000


class BlockKernel(Protocol):
    """What :func:`time_blocks_us` times: ``run(errors (n, C), out (n, C))``."""

    n_channels: int

    def run(self, errors: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Step over the rows of ``errors`` (m/s^2), commands (N) into ``out``."""


def time_blocks_us(kernels: dict[str, BlockKernel], timing: TimingSettings,
                   seed: int = 0) -> dict[str, dict[str, float]]:
    """Per-sample time (us) of compiled kernels that step over a block of errors per call.

    Like :func:`time_steps_us` (round-robin, garbage collector off); each round runs
    one block of ``timing.number`` samples (0.01 m/s^2 RMS random errors) per kernel. A
    first block per kernel compiles it and fills the FxLMS warm-up; it is not timed.

    Returns:
        name -> {"median": us, "min": us}.
    """
    rng = np.random.default_rng(seed)
    runners = {}
    for name, kernel in kernels.items():
        errors = 0.01 * rng.standard_normal((timing.number, kernel.n_channels))
        out = np.zeros_like(errors)
        kernel.run(errors, out)
        runners[name] = functools.partial(kernel.run, errors, out)
    return round_robin_us(runners, timing.number, timing.repeat)


def compiled_equivalence(samples: int = EQUIVALENCE_SAMPLES) -> dict[str, float]:
    """Largest command difference, compiled kernel vs numpy controller, relative to the peak.

    The notch 6x8 and the FxLMS (L=64, 2 tones) of the benchmark step ``samples`` random
    errors both ways from the same state. Needs numba.
    """
    from hexapod_vibration.baseline.compiled_kernels import CompiledFxlms, CompiledNotch

    errors = 0.01 * np.random.default_rng(1).standard_normal((samples, STRUTS))
    pairs = {"notch_6x8": (make_notch(STRUTS, RATIO_NOTCH_TONES, False), CompiledNotch),
             "fxlms_L64": (make_fxlms(DEFAULT_PATH_TAPS, DEFAULT_CONTROL_TAPS),
                           CompiledFxlms)}
    result = {}
    for name, (controller, compiled) in pairs.items():
        kernel = compiled(controller)
        expected = np.array([controller.step(e) for e in errors])
        got = kernel.run(errors, np.zeros_like(errors))
        result[name] = float(np.max(np.abs(got - expected)) / np.max(np.abs(expected)))
    return result


def measure_compiled_costs(timing: TimingSettings) -> dict[str, Any]:
    """Per-sample cost of both controllers compiled (numba): their arithmetic cost.

    Returns ``{"compiled": {...}}``; without numba ``{"compiled": {"skipped": reason}}``.
    """
    try:
        import numba

        from hexapod_vibration.baseline import compiled_kernels
    except ModuleNotFoundError as exc:
        if exc.name != "numba":
            raise
        return {"compiled": {"skipped": "numba is not installed"}}
    t0 = time.perf_counter()
    same_tones = tuple(tone_frequencies(FXLMS_SAME_TONES))
    kernels: dict[str, BlockKernel] = {
        f"notch_6x{t}": compiled_kernels.CompiledNotch(make_notch(STRUTS, t, False))
        for t in COMPILED_NOTCH_TONES}
    for n in COMPILED_FXLMS_PATH_TAPS:
        kernels[f"fxlms_L{n}"] = compiled_kernels.CompiledFxlms(
            make_fxlms(n, DEFAULT_CONTROL_TAPS))
        kernels[f"fxlms_L{n}_{FXLMS_SAME_TONES}tones"] = compiled_kernels.CompiledFxlms(
            make_fxlms(n, DEFAULT_CONTROL_TAPS, tones_hz=same_tones))
    equivalence = compiled_equivalence()                     # also compiles both kernels
    compile_s = time.perf_counter() - t0
    raw = time_blocks_us(kernels, timing)
    med = {name: v["median"] for name, v in raw.items()}
    notch = {f"6x{t}": med[f"notch_6x{t}"] for t in COMPILED_NOTCH_TONES}
    fx = {str(n): med[f"fxlms_L{n}"] for n in COMPILED_FXLMS_PATH_TAPS}
    fx_same = {str(n): med[f"fxlms_L{n}_{FXLMS_SAME_TONES}tones"]
               for n in COMPILED_FXLMS_PATH_TAPS}
    notch_68 = notch[f"6x{RATIO_NOTCH_TONES}"]
    return {"compiled": {
        "engine": f"numba {numba.__version__} (LLVM, fastmath), one call per "
                  f"{timing.number}-sample block",
        "notch_us_per_sample": notch,
        "fxlms_us_per_sample": fx,
        f"fxlms_{FXLMS_SAME_TONES}tones_us_per_sample": fx_same,
        "cost_ratio_fxlms_over_notch_6x8": fx[str(DEFAULT_PATH_TAPS)] / notch_68,
        "cost_ratio_same_tones_6x8": fx_same[str(DEFAULT_PATH_TAPS)] / notch_68,
        "cost_ratio_fxlms_over_notch_6x8_of_minima": (
            raw[f"fxlms_L{DEFAULT_PATH_TAPS}"]["min"] / raw["notch_6x8"]["min"]),
        "max_relative_difference_vs_numpy": equivalence,
        "setup_and_compile_s": compile_s,
        "timings_us_per_sample": raw,
    }}
