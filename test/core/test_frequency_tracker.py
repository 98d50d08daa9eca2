"""Frequency tracking alone and in the notch supervisor, on a static plant (seeded, fast).

The plant is ``a_n = g + d_n + K u_{n-1}`` (m/s^2), K a coupled 6x6 gain, with a disturbance
``d`` whose frequency is given per sample; it starts after the supervisor's identification,
so the identified G is exact and only the tracking is under test. The identification
(broadband, as moving tones need) takes the first 10 s; the disturbance starts at
:data:`START_S`, sample :data:`START` (tone identification, 3.2 s: 3.3 s).
"""

import numpy as np
import pytest
from supervisor_checks import assert_refused_and_unchanged

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.frequency_tracker import (
    RATE_BANDWIDTH_MULTIPLE,
    FrequencyTracker,
    acquisition_frequencies,
    combine_orders,
    rate_bandwidth_caps_hz,
    strongest_lines_hz,
    tracking_bounds_hz,
    weight_phase_error,
)
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.control.plant_identification import PlantFrequencyResponse
from hexapod_vibration.core.control.supervisor import rate_policy
from hexapod_vibration.core.control.supervisor.retuning import P_RETUNE_CHANGE

FS = 1000.0
GRAVITY = 9.80665
K = 0.1 * (np.eye(6) + 0.1 * (np.ones((6, 6)) - np.eye(6)))
MIX = np.linspace(0.5, 1.5, 6)
START_S = 10.3
"""The disturbance starts here (s): after the identification (10 s) and its analysis."""
START = int(START_S * FS)


def supervisor(tones, **changes) -> NotchSupervisor:
    """A supervisor that identifies from the first sample (broadband, 10 s) and is enabled."""
    cfg = NotchConfig().replaced({"tone_frequencies_hz": tones, "identify_delay_s": 0.0,
                                  "frequency_tracking": True, **changes})
    return NotchSupervisor(cfg, FS)


def run(sup, frequencies_hz, amplitudes, start_s: float, samples: int, seed: int = 0,
        reference=None, first: int = 0, enable_at: int | None = None):
    """Close the loop; returns the disturbance-free residual (samples, 6) and estimates.

    ``frequencies_hz(n)`` gives the disturbance tones' frequencies (Hz) at sample n; the
    disturbance is 0 before ``start_s``. ``reference(n)``: a tachometer value or None.
    ``enable_at``: the sample control is switched on (a supervisor built disabled).
    """
    rng = np.random.default_rng(seed)
    u = np.zeros(6)
    phase = rng.uniform(0, 2 * np.pi, len(amplitudes))
    residual = np.zeros((samples, 6))
    estimates = np.zeros((samples, len(sup.config.tone_frequencies_hz)))
    start = int(start_s * FS)
    for n in range(samples):
        phase += 2 * np.pi * np.asarray(frequencies_hz(n)) / FS
        d = MIX * float(np.sum(np.asarray(amplitudes) * np.cos(phase))) * (n >= start)
        residual[n] = d + K @ u
        if reference is not None and reference(n) is not None:
            sup.set_reference_frequency(reference(n), n)
        if n == enable_at:
            sup.apply({"enabled": True})
        u = sup.step(first + n, GRAVITY + residual[n] + 1e-4 * rng.standard_normal(6)).copy()
        estimates[n] = sup.tone_estimates_hz
    return residual, estimates


def demodulated_rms(x: np.ndarray, frequency_hz, first: int) -> float:
    """RMS of the component of x[first:] (all channels) at the (moving) frequency."""
    f = np.broadcast_to(np.asarray(frequency_hz, float), (x.shape[0],))
    phase = 2 * np.pi * np.cumsum(f) / FS
    z = x[first:] * np.exp(-1j * phase[first:, None])
    kernel = np.hanning(400)
    kernel /= kernel.sum()
    base = np.array([np.convolve(z[:, i], kernel, mode="valid") for i in range(6)])
    return float(np.sqrt(2 * np.mean(np.abs(base) ** 2)))


# ------------------------------------------------------------------ the pure pieces
def test_bounds_keep_close_tones_apart_and_within_the_range():
    lower, upper = tracking_bounds_hz([40.0, 39.0, 80.0], 2.0, FS)
    assert lower.tolist() == pytest.approx([39.6, 37.0, 78.0])
    assert upper.tolist() == pytest.approx([42.0, 39.4, 82.0])
    assert upper[1] < lower[0]
    with pytest.raises(ValueError, match="tracking_range_hz"):
        tracking_bounds_hz([40.0], -1.0, FS)


def test_phase_error_is_the_weights_turn_over_mu_and_none_without_a_measurement():
    w = np.exp(1j * np.linspace(0, 3, 12)).reshape(2, 6)
    turned = w * np.exp(1j * np.array([[1e-3], [-2e-3]]))
    g = np.broadcast_to(0.1 * np.exp(-0.7j) * np.eye(6), (2, 6, 6))
    p_inv = np.linalg.inv(-2.0 * np.linalg.inv(g))            # decentralized P = -2/G_ii
    error, strength = weight_phase_error(w, turned, 0.002, 8, g, p_inv)
    assert error == pytest.approx([1e-3 / 0.016, -2e-3 / 0.016], rel=2e-3)
    assert np.all(strength > 0)
    for previous, current, rate in ((w, turned, 0.0), (0 * w, turned, 0.002),
                                    (w, 2 * turned, 0.002)):   # frozen, zero, growing
        error, strength = weight_phase_error(previous, current, rate, 8, g, p_inv)
        assert not np.any(strength) and not np.any(error)


def test_phase_error_is_measured_through_the_plant_on_a_coupled_one():
    rng = np.random.default_rng(3)
    g = (0.1 * np.eye(6) + 0.03 * rng.standard_normal((6, 6))
         + 0.03j * rng.standard_normal((6, 6)))[None]
    p = np.diag(-2.0 / np.diag(g[0]))[None]                   # decentralized
    target = rng.standard_normal((1, 6)) + 1j * rng.standard_normal((1, 6))
    w = target.copy()                                         # converged on T
    psi = 0.01                                                # T turns by psi
    residual = np.einsum("tij,tj->ti", g, w - target * np.exp(1j * psi))
    moved = w + 0.002 * 8 * 0.5 * np.einsum("tij,tj->ti", p, residual)
    error, _ = weight_phase_error(w, moved, 0.002, 8, g, np.linalg.inv(p))
    assert error == pytest.approx([psi], rel=0.02)


def test_orders_combine_to_one_fundamental_error():
    error = np.array([[0.1, 0.0], [0.2, 0.0], [0.3, 0.0]])    # order k sees k x 0.1
    strength = np.array([[1.0, 0.0], [4.0, 0.0], [0.5, 0.0]])
    combined, valid = combine_orders(error, strength, np.array([1.0, 2.0, 3.0]))
    assert combined[0] == pytest.approx(0.1) and valid.tolist() == [True, False]


def test_the_loop_holds_without_measurements_and_stays_in_its_bounds():
    tracker = FrequencyTracker([40.0], 1.0, FS)
    for _ in range(100):
        f = tracker.update(np.array([0.3]), np.array([False]), 0.002)
    assert f == pytest.approx([40.0])
    for _ in range(5000):
        f = tracker.update(np.array([0.5]), np.array([True]), 0.002)
    assert f == pytest.approx([41.0]) and tracker.estimates_hz == pytest.approx([41.0])


# ------------------------------------------------------------------ in the supervisor
def test_a_tone_off_by_0p4_hz_is_tracked_and_cancelled():
    sup = supervisor([40.0])
    residual, est = run(sup, lambda n: [40.4], [0.05], START_S, START + 8700)
    assert sup.state == NotchState.ADAPTING
    assert est[-1000:, 0].mean() == pytest.approx(40.4, abs=1e-3)
    assert np.abs(est[-1000:, 0] - 40.4).max() < 0.02
    status = sup.status()
    assert status["frequency_tracking"] and status["reference"] == "unused"
    assert status["tone_estimates_hz"] == pytest.approx(est[-1].tolist())
    before = demodulated_rms(residual[:START + 700], 40.4, START)
    after = demodulated_rms(residual, 40.4, START + 6700)
    assert 20 * np.log10(before / after) > 40.0


def test_without_tracking_the_same_offset_is_not_followed():
    sup = supervisor([40.0], frequency_tracking=False)
    _, est = run(sup, lambda n: [40.4], [0.05], START_S, START + 1700)
    assert est[-1, 0] == 40.0 and sup.canceller.tone_frequencies_hz.tolist() == [40.0]


def test_close_tones_are_tracked_each_to_its_own_frequency():
    sup = supervisor([39.0, 40.0])
    _, est = run(sup, lambda n: [39.2, 40.25], [0.05, 0.05], START_S, START + 13700)
    assert est[-1000:].mean(axis=0) == pytest.approx([39.2, 40.25], abs=5e-3)
    assert np.all(np.diff(est, axis=1) > 0.2)          # never met


def test_a_tone_outside_the_range_stops_at_its_edge():
    sup = supervisor([40.0], tracking_range_hz=0.3)
    _, est = run(sup, lambda n: [40.45], [0.05], START_S, START + 4700)
    assert est.max() == pytest.approx(40.3)


def test_frozen_weights_hold_the_frequency():
    sup = supervisor([40.0])
    frozen = START + 3708                           # 8 samples before a block ends
    run(sup, lambda n: [40.4], [0.05], START_S, frozen)
    sup.canceller.set_frozen(True)
    held = sup.follower.tracker.estimates_hz        # the proportional correction ends
    _, est = run(sup, lambda n: [40.9], [0.05], start_s=0.0, samples=1000, first=frozen)
    assert np.all(est[8:] == held)


def test_the_oscillators_move_phase_continuously_and_keep_their_weights():
    sup = supervisor([40.0])
    run(sup, lambda n: [40.0], [0.05], START_S, START + 700)
    canceller = sup.canceller
    w, phase = canceller.weights, canceller.phases_rad
    canceller.retune(np.array([40.5]))
    assert np.array_equal(canceller.weights, w)
    assert canceller.phases_rad == pytest.approx(phase, abs=1e-12)
    for _ in range(10):
        canceller.step(np.zeros(6))
    assert canceller.phases_rad == pytest.approx(
        np.remainder(phase + 10 * 2 * np.pi * 40.5 / FS, 2 * np.pi), abs=1e-9)


# ------------------------------------------------------------------ settings, reference
@pytest.mark.parametrize("changes, reason", [
    ({"tone_frequencies_hz": [40.0, 50.0, 60.0, 70.0, 90.0, 110.0], "harmonics": 2},
     "at most 16"),
    ({"tone_frequencies_hz": [260.0], "harmonics": 1, "frequency_tracking": False},
     "reaches fs/2"),
    ({"tone_frequencies_hz": [160.0], "harmonics": 2, "tracking_range_hz": 7.0},
     "reaches fs/2"),
    ({"tone_frequencies_hz": [40.0, 80.0], "harmonics": 1}, "duplicate"),
    ({"reference_harmonics": [1.0]}, "one order per tone"),
    ({"reference_harmonics": [1.0, -2.0]}, "> 0"),
    ({"harmonics": 16}, r"harmonics must be in \[0, 15\]"),
    ({"tracking_range_hz": -1.0}, "tracking_range_hz"),
    ({"reference_timeout_s": 0.0}, "reference_timeout_s"),
    # the ranges are the parameter declarations' (parameter_specs), in the core too
    ({"tracking_range_hz": 0.0}, r"tracking_range_hz must be in \(0, 50\] Hz"),
    ({"tracking_range_hz": 60.0}, r"tracking_range_hz must be in \(0, 50\] Hz"),
    ({"reference_timeout_s": 0.001}, r"reference_timeout_s must be in \[0.002, 10\] s"),
])
def test_bad_moving_tone_settings_are_refused_and_change_nothing(changes, reason):
    sup = supervisor([40.0, 80.0])
    assert_refused_and_unchanged(sup, changes, reason)
    assert sup.canceller.tone_frequencies_hz.tolist() == [40.0, 80.0]


def test_harmonics_put_orders_in_the_bank_and_identify_them():
    sup = supervisor([40.0, 50.0], harmonics=2)
    assert sup.canceller.tone_frequencies_hz.tolist() == [40.0, 50.0, 80.0, 100.0, 120.0, 150.0]
    assert sup.status()["bank_tones_hz"] == [40.0, 50.0, 80.0, 100.0, 120.0, 150.0]
    sup.step(0, np.full(6, GRAVITY))
    assert "[40.0, 50.0, 80.0, 100.0, 120.0, 150.0]" in sup.drain_events()[0].message
    sup.apply({"harmonics": 0})
    assert sup.canceller.tone_frequencies_hz.tolist() == [40.0, 50.0]


def test_tones_follow_the_reference_and_hold_when_it_goes_stale():
    sup = supervisor([30.0, 45.0], reference_harmonics=[1.0, 1.5], harmonics=1,
                     frequency_tracking=False, reference_timeout_s=0.05)
    assert sup.status()["reference"] == "waiting"
    speed = lambda n: 30.5 + 0.5e-3 * max(n - START, 0)         # noqa: E731  (0.5 Hz/s)
    stale = START + 3700
    residual, est = run(sup, lambda n: [speed(n), 3 * speed(n)], [0.05, 0.03], START_S,
                        stale + 1000, reference=lambda n: speed(n) if n < stale else None)
    # the tones are set once per 16-sample block, for its middle: within 1.5 x 0.5 Hz/s x 16 ms
    assert est[stale - 10] == pytest.approx([speed(stale - 10), 1.5 * speed(stale - 10)],
                                            abs=0.012)
    # stale from 50 samples later on: the tones hold where the reference (extrapolated
    # along its slope while fresh) had them, not back to nominal
    held = sup.tone_estimates_hz
    assert held == pytest.approx([speed(stale + 50), 1.5 * speed(stale + 50)], abs=0.012)
    assert sup.canceller.tone_frequencies_hz == pytest.approx(
        [held[0], held[1], 2 * held[0], 2 * held[1]])
    status = sup.status()
    assert status["reference"] == "stale" and status["tone_estimates_hz"] == held.tolist()
    messages = " | ".join(e.message for e in sup.drain_events())
    assert "following the reference" in messages and "stale" in messages
    assert f"hold at {np.round(held, 3).tolist()} Hz" in messages
    ramp = demodulated_rms(residual[:stale - 10], [speed(n) for n in range(stale - 10)],
                           stale - 1000)
    assert 20 * np.log10(0.05 / ramp) > 40.0     # at nominal tones: 3 dB (measured)


def test_a_stale_reference_hands_over_to_tracking_where_the_tones_are():
    """A spin-up on the tachometer whose reference stops mid-ramp: tracking takes over.

    The tracker starts where the reference had the tones, at the reference's rate (Hz/s),
    and keeps the tone cancelled; it does not go back to the line of the record taken
    before control on (the acquisition belongs to the start of adaptation, not to a
    handover: 2 s before, at 30.5 Hz).
    """
    sup = supervisor([30.0], reference_harmonics=[1.0], reference_timeout_s=0.05,
                     tracking_range_hz=10.0, enabled=False)
    on = START + 1700                                          # control on
    speed = lambda n: 30.5 + 1e-3 * max(n - on - 1000, 0)       # noqa: E731  (1 Hz/s)
    stale = on + 3000
    residual, est = run(sup, lambda n: [speed(n)], [0.05], START_S, stale + 1000,
                        enable_at=on, reference=lambda n: speed(n) if n < stale else None)
    messages = " | ".join(e.message for e in sup.drain_events())
    assert "reference frequency stale" in messages and "acquisition at" not in messages
    assert "tracking from there at the reference's last rate [1.0] Hz/s" in messages
    assert sup.status()["reference"] == "stale"
    # coasting on the reference's rate, then tracking: within 0.05 Hz of the line
    assert np.max(np.abs(est[stale + 50:stale + 1000, 0]
                         - [speed(n) for n in range(stale + 50, stale + 1000)])) < 0.05
    after = demodulated_rms(residual, [speed(n) for n in range(stale + 1000)], stale + 50)
    assert 20 * np.log10(0.05 / after) > 30.0


def static_plant_response(delay_samples: int = 1):
    """The harness plant's exact G(f) = K e^{-j 2 pi f d / fs} as a broadband response."""
    lines = np.arange(1.0, 500.0, 1.0)
    phase = np.exp(-2j * np.pi * lines * delay_samples / FS)[:, None]
    return PlantFrequencyResponse(FS, tuple(lines for _ in range(6)),
                                  tuple(K[:, j][None, :] * phase for j in range(6)),
                                  tuple(np.zeros(lines.size) for _ in range(6)))


def test_a_moved_tone_takes_p_from_the_broadband_response_and_keeps_cancelling():
    """A 2 Hz/s ramp 30 -> 60 Hz: P follows G(f), the tone stays more than 40 dB down.

    P ends within P_RETUNE_CHANGE of G(f) at the tone; it moved by about 18 % on the way.
    """
    sup = supervisor([30.0], reference_harmonics=[1.0], frequency_tracking=False)
    response = static_plant_response()
    speed = lambda n: 30.0 + 2e-3 * max(n - START - 1700, 0)   # noqa: E731  (2 Hz/s)

    def reference(n):                 # the exact G(f) once the identification ends
        if sup.plant_response is not None:
            sup.plant_frequency_response = response
        return speed(n)

    samples = START + 16700
    residual, _ = run(sup, lambda n: [speed(n)], [0.05], START_S, samples, reference=reference)
    p_start = adaptation.normalized_coefficients(response.at(np.array([30.0])), "decentralized")
    g = sup.plant_frequency_response.at(sup.canceller.tone_frequencies_hz)
    p_expected = adaptation.normalized_coefficients(g, "decentralized")
    assert sup.canceller.tone_frequencies_hz[0] == pytest.approx(speed(samples - 1), abs=0.02)
    change = np.linalg.norm(sup.canceller.coefficients - p_expected) / np.linalg.norm(p_expected)
    assert change < P_RETUNE_CHANGE
    assert np.linalg.norm(p_start - p_expected) > 1.5 * P_RETUNE_CHANGE * np.linalg.norm(p_expected)
    ramp = demodulated_rms(residual, [speed(n) for n in range(samples)], START + 3700)
    assert 20 * np.log10(0.05 / ramp) > 40.0


def test_acquisition_takes_the_strongest_line_within_each_tones_bounds():
    """Close tones 39 and 40 Hz: each takes only lines on its own side of 39.5 Hz."""
    lines = np.array([38.6, 39.45, 40.4, 41.0, 45.0])
    strength = np.array([1.0, 5.0, 3.0, 2.0, 9.0])
    found = acquisition_frequencies([39.0, 40.0], 2.0, FS, lines, strength)
    assert found.tolist() == [38.6, 40.4]       # 39.45 is past the midpoint less 0.1 Hz
    assert np.isnan(acquisition_frequencies([30.0], 2.0, FS, lines, strength)).all()


def test_strongest_line_of_a_record_to_a_hundredth_of_a_hertz():
    rng = np.random.default_rng(7)
    n = np.arange(1000)
    record = (0.05 * MIX * np.cos(2 * np.pi * 40.43 * n / FS + 0.2)[:, None]
              + 0.004 * np.cos(2 * np.pi * 47.0 * n / FS)[:, None]
              + 1e-3 * rng.standard_normal((1000, 6)))
    found = strongest_lines_hz(record, FS, np.array([38.0, 60.0]), np.array([42.0, 70.0]))
    assert found[0] == pytest.approx(40.43, abs=0.01)
    assert np.isnan(found[1])                              # noise only: no line


def test_a_recentred_tracker_is_bounded_around_its_new_place():
    tracker = FrequencyTracker([30.0, 60.0], 2.0, FS)
    tracker.reset([45.0, 90.0])
    assert tracker.frequencies_hz.tolist() == [32.0, 62.0]        # clamped to nominal +- 2
    tracker.recentre([45.0, 90.0])
    assert tracker.frequencies_hz.tolist() == [45.0, 90.0]
    assert tracker.upper_hz.tolist() == [47.0, 92.0]


def test_a_tone_0_4_hz_off_is_acquired_from_the_broadband_identification():
    """Pull-in: 40.4 Hz told 40 Hz at a rate whose lock range is ~0.1 Hz.

    The broadband identification's fitted line puts the oscillator at 40.4 Hz (event,
    ``acquired_hz``), P from G(f) there; the tracker only fine-tracks: >= 40 dB.
    """
    sup = supervisor([40.0], identification="broadband", mu=0.001)
    residual, est = run(sup, lambda n: [40.4], [0.05], 0.0, 19000)
    assert sup.status()["acquired_hz"] == pytest.approx([40.4], abs=0.005)
    assert "acquisition: tones 40 -> 40.400 Hz" in " | ".join(
        e.message for e in sup.drain_events())
    assert est[-1] == pytest.approx([40.4], abs=0.01)
    assert sup.status()["guard_bands"] == "following" and sup.state == NotchState.ADAPTING
    assert 20 * np.log10(0.05 / demodulated_rms(residual, 40.4, 16000)) > 40.0


SWEEP = START - 3300
"""The sweep run's timeline (below) after the identification: its samples shifted by this."""


def _sweep_run(sup, samples=SWEEP + 12000):
    """A tachometer rotor: 30 Hz, 2 Hz/s for 4 s from 1.7 s after the disturbance, then 38 Hz.

    The disturbance path has a 5 ms delay and the amplitude grows with speed^2 (its phasor
    moves as it sweeps). Returns the residual (samples, 6), the speed per sample and the
    canceller's integral ratios and weight rates at 4.9, 8, 9.05 and 11.9 s after
    :data:`SWEEP` (before, during, just after the sweep and once its hold is over).
    """
    response = static_plant_response()
    speed = np.clip(30.0 + 2e-3 * (np.arange(samples) - SWEEP - 5000), 30.0, 38.0)
    phase, u = 0.4, np.zeros(6)
    residual = np.zeros((samples, 6))
    ratios = {}
    rng = np.random.default_rng(2)
    for n in range(samples):
        phase += 2 * np.pi * speed[n] / FS
        path = phase - 2 * np.pi * speed[n] * 0.005
        d = MIX * 0.05 * (speed[n] / 30.0) ** 2 * np.cos(path) * (n >= START)
        residual[n] = d + K @ u
        if sup.plant_response is not None:
            sup.plant_frequency_response = response
        sup.set_reference_frequency(speed[n], n)
        u = sup.step(n, GRAVITY + residual[n] + 1e-5 * rng.standard_normal(6)).copy()
        if n - SWEEP in (4900, 8000, 9050, 11900):
            ratios[n - SWEEP] = (sup.canceller.integral_ratio.copy(), sup.canceller.weight_rates)
    return residual, speed, ratios


def test_a_sweeping_tone_adapts_with_the_rate_integrator_only_while_it_sweeps(monkeypatch):
    """The type-2 update follows a sweeping disturbance the first-order one lags.

    On while the reference sweeps (the paper's update lags by its time constant); steady
    tones have none.
    """
    def reduction(residual, speed):
        end = SWEEP + 8900
        return 20 * np.log10(0.05 * (34.0 / 30.0) ** 2
                             / demodulated_rms(residual[:end], speed[:end], SWEEP + 6500))

    settings = dict(reference_harmonics=[1.0], frequency_tracking=False, mu=0.005)
    residual, speed, ratios = _sweep_run(supervisor([30.0], **settings))
    with_integral = reduction(residual, speed)
    assert not np.any(ratios[4900][0])                      # steady: the paper's update
    ratio = rate_policy.MOVING_TONE_INTEGRAL_RATIO
    assert ratios[8000][0] == pytest.approx([ratio]) and np.any(ratios[8000][1])
    # the sweep stops at 9 s: the learnt rate goes with the reference's slope at once, the
    # update stays type 2 for 10 time constants (2 s), then it is the paper's again
    assert ratios[9050][0] == pytest.approx([ratio])
    assert np.abs(ratios[9050][1]).max() < 0.05 * np.abs(ratios[8000][1]).max()
    assert not np.any(ratios[11900][0]) and not np.any(ratios[11900][1])
    monkeypatch.setattr(rate_policy, "MOVING_TONE_INTEGRAL_RATIO", 0.0)
    residual, speed, ratios = _sweep_run(supervisor([30.0], **settings))
    without = reduction(residual, speed)
    assert not np.any(ratios[8000][0])
    assert without < 40.0 and with_integral > without + 20.0, (without, with_integral)


def test_the_tracking_loop_is_at_most_eight_times_as_fast_as_its_weights():
    """Natural frequency and proportional corner <= 8 mu_k fs / (2 pi k), the slowest order.

    At the weights' own rate the loop is a second feedback path on the tone that the
    predicted sensitivity leaves out (on the PPH, 1.5 Hz beside weights at 0.1-0.14 Hz:
    +1.1..+1.5 dB at 50 Hz over the twin); it follows the rates in force: the policy's
    after the identification, and ``mu`` when it changes.
    """
    caps = rate_bandwidth_caps_hz([1.0, 2.0], [0.001, 0.002, 0.0006, 0.004], FS)
    slowest = np.array([min(0.001, 0.0006 / 2), min(0.002, 0.004 / 2)])
    assert caps == pytest.approx(RATE_BANDWIDTH_MULTIPLE * slowest * FS / (2 * np.pi))
    tracker = FrequencyTracker([40.0], 2.0, FS)
    assert tracker.bandwidths_hz == pytest.approx([1.5])
    tracker.limit_bandwidth(0.5)
    assert tracker.bandwidths_hz == pytest.approx([0.5])
    tracker.limit_bandwidth(10.0)                        # the built bandwidth comes back
    assert tracker.bandwidths_hz == pytest.approx([1.5])
    sup = supervisor([40.0], mu=0.001)
    run(sup, lambda n: [40.2], [0.05], START_S, START + 500)
    assert sup.status()["tone_mu"] == [0.001]
    expected = RATE_BANDWIDTH_MULTIPLE * 0.001 * FS / (2 * np.pi)       # 1.27 Hz < 1.5 Hz
    assert sup.follower.tracker.bandwidths_hz == pytest.approx([expected])
    sup.apply({"mu": 0.0005})
    run(sup, lambda n: [40.2], [0.05], 0.0, 100, first=START + 500)
    assert sup.follower.tracker.bandwidths_hz == pytest.approx([expected / 2])
