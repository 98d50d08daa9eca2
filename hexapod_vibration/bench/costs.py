"""The controllers' cost per sample: notch and FxLMS, their ratio, scaling, multiply-adds."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hexapod_vibration.baseline.fxlms import (
    DEFAULT_CONTROL_TAPS,
    DEFAULT_FXLMS_MU,
    DEFAULT_PATH_TAPS,
    multiply_adds_per_sample,
)
from hexapod_vibration.bench.controllers import (
    FXLMS_TONES_HZ,
    STRUTS,
    UPDATE_LOWPASS_BENCH_HZ,
    line_monitored_step,
    make_fxlms,
    make_notch,
    make_tracking_supervisor,
    notch_multiply_adds,
    numpy_floor_step,
    tone_frequencies,
)
from hexapod_vibration.bench.timing import Step, TimingSettings, time_steps_us

NOTCH_TONES = (1, 2, 4, 8, 16)
SCALING_CHANNELS = (1, 2, 3, 6, 12)
SCALING_CHANNEL_TONES = 8
LARGE_TONES = (16, 32, 64, 128, 256)
FXLMS_PATH_TAPS = (32, 64, 128)
RATIO_NOTCH_TONES = 8
# the FxLMS also timed with as many tones as the notch of the headline ratio
FXLMS_SAME_TONES = RATIO_NOTCH_TONES
TRACKING_MODES = ("fixed", "tracking", "reference")
TRACKING_TARGET_US = 5.0        # target: tracking adds at most a few us per sample at 6x8


def linear_fit(x: Sequence[float], y: Sequence[float]) -> dict[str, float]:
    """Least-squares line ``y = slope x + intercept`` and its coefficient of determination."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    slope, intercept = np.polyfit(xa, ya, 1)
    resid = ya - (slope * xa + intercept)
    total = np.sum((ya - ya.mean()) ** 2)
    r2 = 1.0 - float(np.sum(resid ** 2) / total) if total > 0.0 else 1.0
    return {"slope": float(slope), "intercept": float(intercept), "r2": r2}


def cost_configurations(quick: bool) -> dict[str, tuple[Step, int]]:
    """Every controller configuration the benchmark times: name -> (step, channels)."""
    tones = set(NOTCH_TONES) | set(LARGE_TONES) | (set() if quick else set(range(1, 17)))
    configs: dict[str, tuple[Step, int]] = {}
    for t in sorted(tones):
        configs[f"notch_dec_6x{t}"] = (make_notch(STRUTS, t, False).step, STRUTS)
    for t in NOTCH_TONES:
        configs[f"notch_cen_6x{t}"] = (make_notch(STRUTS, t, True).step, STRUTS)
    for c in SCALING_CHANNELS:
        if c != STRUTS:
            configs[f"notch_dec_{c}x{SCALING_CHANNEL_TONES}"] = (
                make_notch(c, SCALING_CHANNEL_TONES, False).step, c)
    for n in FXLMS_PATH_TAPS:
        configs[f"fxlms_L{n}"] = (make_fxlms(n, DEFAULT_CONTROL_TAPS).step, STRUTS)
        configs[f"fxlms_L{n}_{FXLMS_SAME_TONES}tones"] = (
            make_fxlms(n, DEFAULT_CONTROL_TAPS,
                       tones_hz=tuple(tone_frequencies(FXLMS_SAME_TONES))).step, STRUTS)
    configs["numpy_floor_6x8"] = (numpy_floor_step(STRUTS, RATIO_NOTCH_TONES), STRUTS)
    lowpassed = make_notch(STRUTS, RATIO_NOTCH_TONES, False)
    lowpassed.set_update_lowpass(UPDATE_LOWPASS_BENCH_HZ)
    configs[f"notch_dec_6x{RATIO_NOTCH_TONES}_update_lowpass"] = (lowpassed.step, STRUTS)
    configs[f"notch_dec_6x{RATIO_NOTCH_TONES}_line_monitor"] = (
        line_monitored_step(STRUTS, RATIO_NOTCH_TONES), STRUTS)
    for mode in TRACKING_MODES:
        configs[f"supervisor_6x{RATIO_NOTCH_TONES}_{mode}"] = (
            make_tracking_supervisor(RATIO_NOTCH_TONES, mode), STRUTS)
    return configs


def measure_costs(timing: TimingSettings, quick: bool) -> dict[str, Any]:
    """Every timing of the benchmark (notch, FxLMS, scaling), in us per sample."""
    raw = time_steps_us(cost_configurations(quick), timing)
    med = {name: v["median"] for name, v in raw.items()}
    notch = {f"6x{t}": med[f"notch_dec_6x{t}"] for t in NOTCH_TONES}
    central = {f"6x{t}": med[f"notch_cen_6x{t}"] for t in NOTCH_TONES}
    fx_by_l = {str(n): med[f"fxlms_L{n}"] for n in FXLMS_PATH_TAPS}
    fx_same = {str(n): med[f"fxlms_L{n}_{FXLMS_SAME_TONES}tones"] for n in FXLMS_PATH_TAPS}
    fx = fx_by_l[str(DEFAULT_PATH_TAPS)]
    floor = med["numpy_floor_6x8"]
    return {
        **_added_costs(med, notch[f"6x{RATIO_NOTCH_TONES}"]),
        "notch_us_per_sample": notch,
        "notch_centralized_us_per_sample": central,
        "fxlms_us_per_sample": fx,
        "fxlms_config": {"errors": STRUTS, "actuators": STRUTS,
                         "secondary_path_taps": DEFAULT_PATH_TAPS,
                         "control_taps": DEFAULT_CONTROL_TAPS,
                         "reference_tones": len(FXLMS_TONES_HZ),
                         "references": "one per tone", "mu": DEFAULT_FXLMS_MU},
        "cost_ratio_fxlms_over_notch_6x8": fx / notch[f"6x{RATIO_NOTCH_TONES}"],
        "cost_ratio_fxlms_over_notch_6x2": fx / notch["6x2"],
        f"fxlms_{FXLMS_SAME_TONES}tones_us_per_sample": fx_same,
        "cost_ratio_same_tones_6x8": (fx_same[str(DEFAULT_PATH_TAPS)]
                                      / notch[f"6x{RATIO_NOTCH_TONES}"]),
        "numpy_floor_us_per_sample": floor,
        "numpy_floor_calls": 5,
        # no NumPy notch can be faster than the floor, so no NumPy comparison with these
        # FxLMS configurations can show a larger ratio than this
        "numpy_cost_ratio_bound": max(max(fx_by_l.values()), max(fx_same.values())) / floor,
        "cost_ratio_fxlms_over_notch_6x8_of_minima": (
            raw[f"fxlms_L{DEFAULT_PATH_TAPS}"]["min"] / raw["notch_dec_6x8"]["min"]),
        "timings_us_per_sample": raw,
        "multiply_adds_per_sample": _multiply_adds(),
        "scaling": _scaling(med, quick, fx_by_l),
    }


def _added_costs(med: dict[str, float], notch_68: float) -> dict[str, Any]:
    """What the line-offset monitor, the update low-pass and tone following add (us per sample).

    From the timings' medians ``med``, against the 6x8 notch's ``notch_68``.
    """
    supervisor = {mode: med[f"supervisor_6x{RATIO_NOTCH_TONES}_{mode}"]
                  for mode in TRACKING_MODES}
    lowpass = med[f"notch_dec_6x{RATIO_NOTCH_TONES}_update_lowpass"]
    monitored = med[f"notch_dec_6x{RATIO_NOTCH_TONES}_line_monitor"]
    return {
        "line_offset_monitor_us_per_sample": {
            f"notch_dec_6x{RATIO_NOTCH_TONES}": monitored,
            "added": monitored - notch_68},
        "update_lowpass_us_per_sample": {
            f"notch_dec_6x{RATIO_NOTCH_TONES}": lowpass,
            "added": lowpass - notch_68,
            "corner_hz": UPDATE_LOWPASS_BENCH_HZ},
        "tracking_us_per_sample": {
            "supervisor_6x8": supervisor,
            "added_by_tracking": supervisor["tracking"] - supervisor["fixed"],
            "added_by_reference": supervisor["reference"] - supervisor["fixed"],
            "target_added_us": TRACKING_TARGET_US},
    }


def _multiply_adds() -> dict[str, Any]:
    """Analytic multiply-adds per sample of the notch and the FxLMS, and their ratios."""
    fx_macs = multiply_adds_per_sample(STRUTS, STRUTS, DEFAULT_PATH_TAPS,
                                       DEFAULT_CONTROL_TAPS, len(FXLMS_TONES_HZ))
    return {
        "notch_6x2": notch_multiply_adds(STRUTS, 2, False),
        "notch_6x8": notch_multiply_adds(STRUTS, 8, False),
        "notch_centralized_6x8": notch_multiply_adds(STRUTS, 8, True),
        "fxlms_6x6_L64_N32_2tones": fx_macs,
        f"fxlms_6x6_L64_N32_{FXLMS_SAME_TONES}tones": multiply_adds_per_sample(
            STRUTS, STRUTS, DEFAULT_PATH_TAPS, DEFAULT_CONTROL_TAPS, FXLMS_SAME_TONES),
        "ratio_fxlms_over_notch_6x8": fx_macs / notch_multiply_adds(STRUTS, 8, False),
        "ratio_fxlms_over_notch_6x2": fx_macs / notch_multiply_adds(STRUTS, 2, False),
    }


def _scaling(med: dict[str, float], quick: bool, fx_by_l: dict[str, float]) -> dict[str, Any]:
    """The scaling sweeps (us per sample) and their linear fits, from the medians ``med``."""
    tones = list(NOTCH_TONES) if quick else list(range(1, 17))
    by_tone = {str(t): med[f"notch_dec_6x{t}"] for t in tones}
    by_channel = {str(c): med[f"notch_dec_{c}x{SCALING_CHANNEL_TONES}"] for c in SCALING_CHANNELS}
    large = {str(t): med[f"notch_dec_6x{t}"] for t in LARGE_TONES}
    return {
        "notch_vs_tones": {"channels": STRUTS, "us_per_sample": by_tone,
                           "fit_us_per_tone": linear_fit(tones, list(by_tone.values()))},
        "notch_vs_tones_large": {
            "channels": STRUTS, "us_per_sample": large,
            "fit_us_per_tone": linear_fit(LARGE_TONES, list(large.values()))},
        "notch_vs_channels": {
            "tones": SCALING_CHANNEL_TONES, "us_per_sample": by_channel,
            "fit_us_per_channel": linear_fit(SCALING_CHANNELS, list(by_channel.values()))},
        "fxlms_vs_path_taps": {
            "us_per_sample": fx_by_l,
            "fit_us_per_tap": linear_fit(FXLMS_PATH_TAPS, list(fx_by_l.values())),
            "multiply_adds_per_sample": {
                str(n): multiply_adds_per_sample(STRUTS, STRUTS, n, DEFAULT_CONTROL_TAPS,
                                                 len(FXLMS_TONES_HZ))
                for n in FXLMS_PATH_TAPS}},
        "notch_plant_order": ("the notch holds no plant model: its state and cost are "
                              "T x C weights and T (C x C) coefficients whatever the "
                              "plant order; FxLMS carries I x J x L model taps"),
    }
