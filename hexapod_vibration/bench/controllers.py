"""The controllers the benchmark times: the notch, its supervisor, the FxLMS, the NumPy floor.

Each is built adapting, with random coefficients or paths where the cost does not depend
on their values, and handed out as a ``step(error, out)`` (:data:`~.timing.Step`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexapod_vibration.baseline.fxlms import (
    DEFAULT_CONTROL_TAPS,
    DEFAULT_FXLMS_MU,
    DEFAULT_PATH_TAPS,
    FilteredXLMSController,
)
from hexapod_vibration.bench.timing import Step
from hexapod_vibration.contract import SAMPLE_RATE_HZ, STRUT_COUNT
from hexapod_vibration.core.control.line_offset import LineOffsetMonitor
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor

FS_HZ = SAMPLE_RATE_HZ
STRUTS = STRUT_COUNT
FXLMS_TONES_HZ = (40.0, 80.0)
TRACKING_WARMUP_SAMPLES = 2500  # > 2/mu at mu 1e-3: the tracker measures from then on


UPDATE_LOWPASS_BENCH_HZ = 10.0
"""Corner (Hz) of the update low-pass the benchmark times (the shipped scenarios')."""


def tone_frequencies(n_tones: int) -> np.ndarray:
    """``n_tones`` distinct tones (Hz) between 20 and 480 Hz (cost does not depend on them)."""
    return np.linspace(20.0, 480.0, n_tones) if n_tones > 1 else np.array([40.0])


def make_notch(n_channels: int, n_tones: int, centralized: bool,
               seed: int = 0) -> AdaptiveNotchCanceller:
    """An adapting notch with random coefficients: diagonal P (decentralized) or full P."""
    rng = np.random.default_rng(seed)
    shape = (n_tones, n_channels, n_channels) if centralized else (n_tones, n_channels)
    p = rng.standard_normal(shape) + 1j * rng.standard_normal(shape)
    return AdaptiveNotchCanceller(n_channels, tone_frequencies(n_tones), FS_HZ, mu=1e-3,
                                  coefficients=p)


def make_tracking_supervisor(n_tones: int, mode: str) -> Step:
    """The notch supervisor's step at 6 struts x ``n_tones`` in ``mode``.

    ``fixed`` (nominal tones), ``tracking`` (frequency_tracking on) or ``reference`` (tones
    following a tachometer value given every sample). Raw adaptation (P = I) adapts from
    the first sample, so the step is the whole per-sample path (DC blocker, canceller,
    tone following every block of 16 samples; warmed up past the weights' settling, so
    the phase detector runs).
    """
    tones = tone_frequencies(n_tones).tolist()
    changes = {"tone_frequencies_hz": tones, "adaptation": "raw", "mu": 1e-3,
               "frequency_tracking": mode == "tracking"}
    if mode == "reference":
        changes["reference_harmonics"] = [f / tones[0] for f in tones]
    sup = NotchSupervisor(NotchConfig().replaced(changes), FS_HZ, STRUTS)
    # a plant response for the phase detector (raw mode has no identification); the cost
    # does not depend on its values
    sup.plant_response = -2.0 * np.broadcast_to(np.eye(STRUTS, dtype=complex),
                                                (n_tones, STRUTS, STRUTS)).copy()
    reference = mode == "reference"

    def step(error: np.ndarray, out: np.ndarray) -> np.ndarray:
        if reference:
            sup.set_reference_frequency(tones[0], None)
        out[...] = sup.step(None, error)
        return out

    rng = np.random.default_rng(1)
    for error in 0.01 * rng.standard_normal((TRACKING_WARMUP_SAMPLES, STRUTS)):
        step(error, np.zeros(STRUTS))          # past the settling: the detector runs
    return step


def make_fxlms(path_taps: int = DEFAULT_PATH_TAPS, control_taps: int = DEFAULT_CONTROL_TAPS,
               tones_hz: Sequence[float] = FXLMS_TONES_HZ, n_channels: int = STRUTS,
               seed: int = 0) -> FilteredXLMSController:
    """An adapting FxLMS (one reference per tone) with random decaying paths (cost only)."""
    rng = np.random.default_rng(seed)
    decay = np.exp(-np.arange(path_taps) / 8.0)
    paths = 0.01 * rng.standard_normal((n_channels, n_channels, path_taps)) * decay
    return FilteredXLMSController(paths, tones_hz, FS_HZ, mu=DEFAULT_FXLMS_MU,
                                  n_taps=control_taps)


def line_monitored_step(n_channels: int, n_tones: int) -> Step:
    """The decentralized notch step and the supervisor's line-offset monitor on its weights.

    What a fixed-tone supervisor adds per sample to locate each tone's line (the block mean
    of the adapted weights; the turning itself once per 50 samples).
    """
    notch = make_notch(n_channels, n_tones, centralized=False)
    monitor = LineOffsetMonitor(n_tones, SAMPLE_RATE_HZ)

    def step(error: np.ndarray, out: np.ndarray) -> np.ndarray:
        notch.step(error, out=out)
        monitor.step_from(notch)
        return out

    return step


def numpy_floor_step(n_channels: int, n_tones: int) -> Step:
    """The five array calls any NumPy notch step needs, on a notch's own buffers.

    Demodulate (``e e^{j phi}``, one outer product), scale by the rate (one complex
    product), accumulate the weights, form the output (one matrix-vector product) and
    rotate the phasors: the notch's hot path without its argument checks, branches and
    copy. Its time per call is the floor of any NumPy implementation of the notch step on
    this machine, whatever the arithmetic (``numpy_floor_us_per_sample``).
    """
    notch = make_notch(n_channels, n_tones, centralized=False)
    y, y_r, q, v = notch._y, notch._y_r, notch._q, notch._v
    v_r, z_r, z_row = notch._v_r, notch._z_r, notch._z_row_r
    store, rot = notch._osc._store, notch._osc._rot

    def step(error: np.ndarray, out: np.ndarray) -> np.ndarray:
        np.dot(error[:, None], z_row, out=y_r)
        np.multiply(y, q, out=y)
        np.add(v, y, out=v)
        np.dot(v_r, z_r, out=out)
        np.multiply(store, rot, out=store)
        return out

    return step


def notch_multiply_adds(n_channels: int, n_tones: int, centralized: bool) -> int:
    """Real multiply-adds per sample of the notch (analytic count of its implementation).

    Per tone: phasor rotation (4, one complex product). Per tone and channel:
    decentralized, demodulation e e^{j phi} (2) and rate-scaled coefficient (4, one
    complex product); centralized, coefficient times error (2 C, real) and demodulation
    (4); then weight update (2) and output Re{W e^{j phi}} (2). The paper's raw SISO
    form (P = 1, mu folded into e) needs 4 per tone and channel.
    """
    per = (2 * n_channels + 4) if centralized else (2 + 4)
    return n_tones * (4 + n_channels * (per + 2 + 2))
