"""On the core loop: never worse than off, and saying why; with tracking too.

Each scenario runs twice with the same seeds, with control and without (its twin); over the
report's window (the last 10 s), and over every window that long from control-on (1 s
apart: the start of control, a fade), every one-third-octave band 5..500 Hz and the 8 Hz
band around the told tone of the top plate's z axis must stay within +1 dB of the twin's
(worst windows measured: mismatch +0.70, drift +0.43 (+0.78 when the weights froze at
once), drift_tracking +0.67, single_tone_harmonic +0.92 dB).
``mismatch`` (shaker 40.4 Hz, notch told 40 Hz): the identification survives the line
0.4 Hz off, control works at the rate the policy allows (the tone's band drops); ``drift``
(+-1 Hz, 20 s period): the supervisor locates the line from the weights' turning, sees it
move off the notch (where control gains less than the 1 dB margin) and fades control out
before any band rises, with the reason on /diagnostics (the guard alone would fade out
only once a band had risen);
``drift_tracking`` (the same drift, tracked): the tone's band drops by 30 dB and more while
every other band stays within +1 dB (the weights are not stepped when P follows the tone:
with that step, +2.8..+3.5 dB in 44.7-56.2 Hz); ``single_tone_harmonic`` (paper Table 1,
mu 0.002 with the update low-pass): no band above +1 dB, the 40 Hz band at the floor.
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from core_twins import band_db as _band_db
from core_twins import run_with_twin as _run_with_twin
from core_twins import worst_window_rise as _worst_window_rise

from hexapod_vibration.core.sim.scenario import load_scenario
from hexapod_vibration.core.spectrum import third_octave_bands_hz

ROOT = Path(__file__).resolve().parents[2]
FS = 1000.0


def _twins(name: str):
    """(loop, rise dB per band over the report's window, worst rise over every window).

    The start of control and a fade lie before the report's window: hence every window.
    """
    scenario = load_scenario(ROOT / "config" / "scenarios" / f"{name}.yaml")
    loop, z_on, z_off = _run_with_twin(scenario)
    bands = third_octave_bands_hz(5.0, 450.0)[:, 1:]
    bands = np.vstack([bands, [[36.0, 44.0]]])
    n = int(scenario.window_s * FS)
    rise = _band_db(z_on[-n:], bands) - _band_db(z_off[-n:], bands)
    return loop, rise, _worst_window_rise(scenario, z_on, z_off, bands)


@pytest.mark.parametrize("name", ["mismatch", "drift", "drift_tracking",
                                  "single_tone_harmonic"])
def test_every_band_stays_within_1db_of_its_level_without_control(name):
    loop, rise, worst = _twins(name)
    assert np.max(rise) < 1.0, rise
    assert worst < 1.0, worst          # in every window from control-on, too
    status = loop.notch.status()
    assert loop.notch.plant_frequency_response is not None       # identified with the line
    assert status["identification_confidence"] > 0.9
    if name == "drift_tracking":
        assert status["guard"] == "watching" and rise[-1] < -30.0, rise[-1]
    elif name == "single_tone_harmonic":
        # Table 1 at the paper's mu 0.002: the update low-pass keeps the 18.7 Hz loop mode
        # down (the paper's update: 20 Hz third octave +1.74 dB), the 40 Hz band at the floor
        assert loop.notch.config.update_lowpass_hz > 0.0 and status["tone_mu"] == [0.002] * 2
        assert status["guard"] == "watching" and rise[-1] < -60.0, rise[-1]
    elif name == "mismatch":
        assert status["guard"] == "watching" and rise[-1] < -1.0  # control helps its band
        assert status["predicted_rise_db"] <= 0.7 + 1e-6
        # the line located from the weights' turning: 40.4 Hz, where control still helps
        assert status["line_offset_hz"] == [pytest.approx(0.4, abs=0.01)]
    else:
        # the drifting line located off the notch (> 0.6 Hz, where control would gain
        # less than the 1 dB margin) before any band rose: faded out, saying where it is
        assert status["guard"] == "off" and status["state"] == "refused"
        assert "line off the notch" in status["refusal"], status["refusal"]
        at_hz = float(status["guard_action"].split("its line is at ")[1].split(" Hz")[0])
        assert 40.6 < at_hz <= 41.0, status["guard_action"]
        # mu fell to 0 before the weights froze (no kink of the output's phase), then the
        # output faded; the oscillator stayed on the told tone
        assert loop.notch.canceller.output_gain == 0.0 and loop.notch.canceller.mu == 0.0
        assert loop.notch.canceller.frozen
        assert loop.notch.canceller.tone_frequencies_hz.tolist() == [40.0]


def _following_db(z: np.ndarray, track_hz: np.ndarray, window: int = 1000) -> np.ndarray:
    """Level (dB) of the line at ``track_hz`` (per sample) in consecutive 1 s windows.

    Demodulated along the track's phase and averaged under a Hann window: a band that
    follows the line (about 1.5 Hz wide), whatever its sweep.
    """
    baseband = z * np.exp(-2j * np.pi * np.cumsum(track_hz) / FS)
    w = np.hanning(window)
    rows = baseband[:baseband.size // window * window].reshape(-1, window)
    return 20 * np.log10(np.abs(rows @ w) / w.sum())


def _spin_up_runs(name: str):
    """(loop, z with control, z of the twin, rotor speed per sample Hz) of a spin-up file."""
    scenario = load_scenario(ROOT / "config" / "scenarios" / f"{name}.yaml")
    assert scenario.notch.settings["update_lowpass_hz"] > 0.0
    loop, z_on, z_off = _run_with_twin(scenario)
    speed = scenario.rotor.rotor().speed_hz(np.arange(z_on.size) / FS)
    return scenario, loop, z_on, z_off, speed


def test_spin_up_tracked_meets_the_ramp_and_steady_targets_and_is_never_worse():
    """The spin-up targets on the core loop (no tachometer, tracking, update low-pass).

    Rotor 30 -> 50 Hz at 1 Hz/s (16..36 s), orders 1-3: against the twin, every order's
    following band is >= 30 dB down in every 1 s window of the ramp (17..36 s) and >= 40 dB
    at steady speed (38..50 s); no third octave 5..450 Hz rises by 1 dB over either span.
    (Measured: ramp min 40 / 36 / 44 dB, steady min 58 / 58 / 64 dB, rises +0.21 / +0.54
    dB; with the paper's update the ramp min was 38 / 32 / 14 dB at the rates the policy
    then allowed.)
    """
    scenario, loop, z_on, z_off, speed = _spin_up_runs("spin_up")
    start_s = np.arange(z_on.size // 1000)
    ramp, steady = (start_s >= 17) & (start_s < 36), (start_s >= 38) & (start_s < 50)
    for order in scenario.rotor.orders:
        reduction = (_following_db(z_off, order * speed) - _following_db(z_on, order * speed))
        assert reduction[ramp].min() >= 30.0, (order, np.round(reduction[ramp], 1))
        assert reduction[steady].min() >= 40.0, (order, np.round(reduction[steady], 1))
    bands = third_octave_bands_hz(5.0, 450.0)[:, 1:]
    for lo, hi in ((17, 36), (38, 50)):
        span = slice(lo * 1000, hi * 1000)
        rise = _band_db(z_on[span], bands) - _band_db(z_off[span], bands)
        assert np.max(rise) < 1.0, (lo, hi, np.round(rise, 2))
    assert loop.notch.status()["guard"] == "watching"


def test_spin_up_on_the_tachometer_meets_every_order_from_the_ramp_start():
    """``spin_up_tachometer`` meets the spin-up targets from the ramp's first second.

    >= 30 dB on every order in every 1 s window of the ramp (16..36 s), >= 50 dB over the
    steady 38..50 s, every third octave within +1 dB of the twin in every 12 s window from
    control-on.

    Order 3's weight turns at 0.35 rad/s when the ramp starts (a zero of the disturbance path
    near 90 Hz); at the 0.006 ceiling the policy gave it 0.006 and the first second kept
    24.5 dB. With the 0.012 ceiling it gets 0.0114 (orders 1 and 2 keep theirs): 52.2 dB.
    (Measured: ramp min 42.2 / 35.2 / 51.7 dB, worst 12 s window +0.79 dB.)
    """
    scenario, loop, z_on, z_off, speed = _spin_up_runs("spin_up_tachometer")
    start_s = np.arange(z_on.size // 1000)
    ramp = (start_s >= 16) & (start_s < 36)
    steady = slice(38000, 50000)
    for order in scenario.rotor.orders:
        reduction = (_following_db(z_off, order * speed) - _following_db(z_on, order * speed))
        assert reduction[ramp].min() >= 30.0, (order, np.round(reduction[ramp], 1))
        track = order * speed[steady]
        level = (_following_db(z_off[steady], track, 12000)
                 - _following_db(z_on[steady], track, 12000))
        assert level[0] >= 50.0, (order, level)
    worst = _worst_window_rise(scenario, z_on, z_off, third_octave_bands_hz(5.0, 450.0)[:, 1:])
    assert worst < 1.0, worst
    status = loop.notch.status()
    assert status["guard"] == "watching" and status["reference"] == "following"
    assert status["tone_mu"][2] > 0.01 > max(status["tone_mu"][:2]), status["tone_mu"]



def _limited_twins(weight_limit_n: float):
    """(loop, rise per band in the last window, worst rise): Table 1 with one limit changed."""
    scenario = load_scenario(ROOT / "config" / "scenarios" / "single_tone_harmonic.yaml")
    notch = dataclasses.replace(scenario.notch, settings={**scenario.notch.settings,
                                                          "weight_limit_n": weight_limit_n})
    scenario = dataclasses.replace(scenario, notch=notch)
    loop, z_on, z_off = _run_with_twin(scenario)
    bands = np.vstack([third_octave_bands_hz(5.0, 450.0)[:, 1:], [[36.0, 44.0], [76.0, 84.0]]])
    n = int(scenario.window_s * FS)
    rise = _band_db(z_on[-n:], bands) - _band_db(z_off[-n:], bands)
    return loop, rise, _worst_window_rise(scenario, z_on, z_off, bands[:-2])


def test_a_weight_limit_far_below_the_tones_need_is_refused_saying_so():
    """Table 1 with ``weight_limit_n`` 0.3 N (the 40 Hz tone needs ~2.5 N per strut).

    The clipped 40 Hz weight lifts the 158 Hz third octave; the guard fades control out and
    the reason says that the weights were held at the limit. Before the ceiling clamp the
    run said "ok" (the 63 Hz third octave +1.56 dB, the starved 80 Hz weight turning).
    """
    loop, rise, worst = _limited_twins(0.3)
    status = loop.notch.status()
    assert status["guard"] == "off" and status["state"] == "refused", status
    assert "the weights were held at weight_limit_n 0.3 N" in status["refusal"], status
    assert "raise it" in status["refusal"]
    assert loop.notch.canceller.output_gain == 0.0
    assert worst < 1.0, worst
    assert np.max(np.abs(rise)) < 0.1, rise          # the last window: off, as the twin


def test_a_weight_limit_below_the_tones_need_keeps_every_tone_it_can_afford():
    """``weight_limit_n`` 3 N: 40 Hz clipped at the ceiling, 80 Hz given all it needs.

    The clamp clips the largest tone first: the 80 Hz tone (0.024 N) falls as far as with
    the default 40 N (>= 40 dB), the 40 Hz tone by what the rest of the limit buys. (With
    all tones scaled together 80 Hz fell 16 dB here and 0.4 dB at 1 N.)
    """
    loop, rise, worst = _limited_twins(3.0)
    status = loop.notch.status()
    assert status["guard"] == "watching" and status["weights_held_at_limit"], status
    assert rise[-2] < -15.0 and rise[-1] < -40.0, rise[-2:]
    assert worst < 1.0, worst
