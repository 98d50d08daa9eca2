"""The notch supervisor alone: sequencing, bounds, clamping, refusal and missing samples.

The plant is static with a one-sample command hold (``test/static_rig.py``), so every
number the supervisor derives (G, the bound) follows from ``K`` by hand. The settings are
the paper's (``config/presets/paper.yaml``: test tones, eq. 18, mu at every tone) unless a
test says.
"""

import numpy as np
import pytest
from scipy import signal
from static_rig import FS, GRAVITY, TONE, coupled_gain, run, tone_rms

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.notch import FADE_S
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.control.supervisor import fader, gate
from hexapod_vibration.core.sim.scenario import notch_preset


def config(**changes) -> NotchConfig:
    """The paper's settings (test tones: G at the tone in 3.2 s) at TONE, off, and ``changes``."""
    base = {**notch_preset("paper"), "tone_frequencies_hz": (TONE,), "enabled": False,
            "identify_delay_s": 0.1}
    return NotchConfig().replaced({**base, **changes})


def test_identifies_after_the_delay_then_adapts_and_cancels_once_enabled():
    sup = NotchSupervisor(config())
    duration = 8 * 400                               # C + 2 segments of 0.4 s
    end = 100 + duration
    off = run(sup, coupled_gain(0.0), end + 1000)[end:]
    status = sup.status()
    assert status["identification_start_sample"] == 100
    assert status["identification_end_sample"] == end - 1
    assert sup.state == NotchState.DISABLED         # identified, control still off
    g = np.diagonal(sup.plant_response[0])
    assert np.allclose(np.abs(g), 0.1, rtol=0.05)   # |K_ii| (the DC blocker barely acts)
    sup.apply({"enabled": True})
    assert sup.state == NotchState.ADAPTING
    on = run(sup, coupled_gain(0.0), 6000, end + 1000)
    assert tone_rms(on[-1000:]) < 1e-3 * tone_rms(off)          # more than 60 dB


def test_a_mu_beyond_the_bound_is_refused_and_changes_nothing():
    sup = NotchSupervisor(config())
    run(sup, coupled_gain(0.0), 100 + 3200)
    bound = sup.bound
    assert 0.5 < bound < 0.7                        # lambda = 1, 2-sample delay: 0.618
    before = (sup.config, sup.canceller.mu)
    with pytest.raises(ValueError, match="stability bound"):
        sup.check({"mu": 0.9})
    with pytest.raises(ValueError, match="stability bound"):
        sup.apply({"mu": 0.9})
    assert (sup.config, sup.canceller.mu) == before
    sup.apply({"mu": 0.01})
    assert sup.canceller.mu == 0.01 and sup.config.mu == 0.01


def test_an_identified_bound_below_mu_clamps_mu_at_once_and_says_so():
    k = coupled_gain(0.15)          # eigenvalues of the normalised loop: 1.75 and 0.85
    sup = NotchSupervisor(config(mu=0.4))
    run(sup, k, 100 + 3200)
    p = adaptation.normalized_coefficients(sup.plant_response, "decentralized")
    bound = adaptation.mu_bound(sup.plant_response[0], p[0], 2.0)
    assert bound < 0.4 and sup.bound == pytest.approx(bound)
    assert sup.canceller.mu == pytest.approx(0.5 * bound)      # in force, not only reported
    assert sup.config.mu == pytest.approx(0.5 * bound)
    mirrored = [e.parameter for e in sup.drain_events() if e.parameter]
    assert mirrored == [("mu", pytest.approx(0.5 * bound))]
    sup.check({"mu": 0.5 * bound})                            # the node's mirror is accepted


def test_a_bound_of_zero_keeps_control_off_even_when_enabled():
    k = coupled_gain(1.2)           # an eigenvalue of diag(1/K_ii) K is 1 - 1.2 < 0
    sup = NotchSupervisor(config(mu=0.002, enabled=True))
    run(sup, k, 100 + 3200)
    assert sup.bound == 0.0
    assert sup.state == NotchState.REFUSED
    assert sup.canceller.mu == 0.0 and not sup.canceller.enabled
    assert "bound is 0" in sup.status()["refusal"]
    events = sup.drain_events()
    assert any(e.level == "error" and "control stays off" in e.message for e in events)
    sup.apply({"enabled": True})
    assert sup.state == NotchState.REFUSED and not sup.canceller.enabled
    with pytest.raises(ValueError, match="stability bound 0"):
        sup.check({"mu": 0.001})
    residual = run(sup, k, 2000, 3300)
    free = run(NotchSupervisor(config(tone_frequencies_hz=())), k, 2000, 3300)
    assert np.array_equal(residual, free)           # exactly what no control gives


def test_duplicates_and_out_of_order_samples_are_counted_and_not_used():
    sup = NotchSupervisor(config())
    run(sup, coupled_gain(0.0), 10)
    assert sup.step(9, np.full(6, GRAVITY)) is None
    assert sup.step(3, np.full(6, GRAVITY)) is None
    assert sup.counters["duplicates"] == 2 and sup.last_sample == 9


def test_a_gap_advances_the_phases_and_is_left_out_of_a_running_identification():
    sup = NotchSupervisor(config())
    run(sup, coupled_gain(0.0), 600, skip=frozenset(range(300, 305)))
    assert sup.counters == {"gaps": 1, "missed_samples": 5, "duplicates": 0}
    assert sup.state == NotchState.IDENTIFYING
    assert sup.status()["identification_start_sample"] == 100       # not started again
    events = [e.message for e in sup.drain_events()]
    assert any("5 samples missing before 305" in m for m in events)
    assert not any("restarting" in m for m in events)
    run(sup, coupled_gain(0.0), 3000, 600)
    whole = NotchSupervisor(config())
    run(whole, coupled_gain(0.0), 3600)
    assert sup.status()["identified_tones_hz"] == [TONE] and "refusal" not in sup.status()
    assert sup.bound == pytest.approx(whole.bound, rel=0.01)
    error = np.linalg.norm(sup.plant_response - whole.plant_response)
    assert error < 0.01 * np.linalg.norm(whole.plant_response)  # the 5 held commands' share


def test_an_identification_missing_more_than_five_percent_of_its_samples_is_refused():
    sup = NotchSupervisor(config(enabled=True))
    run(sup, coupled_gain(0.0), 3600, skip=frozenset(range(105, 3300, 10)))
    assert sup.state == NotchState.REFUSED and not sup.canceller.enabled
    refusal = sup.status()["refusal"]
    assert refusal.startswith("identification refused: 240 of its 2400 measured samples "
                              "(10.0 %) missing (> 5 %); control stays off"), refusal
    assert sup.counters["gaps"] == 320                        # every one counted


def test_gaps_are_reported_at_most_once_a_second_of_samples():
    sup = NotchSupervisor(config(tone_frequencies_hz=()))
    skip = frozenset([*range(300, 900, 50), 1500])
    run(sup, coupled_gain(0.0), 1600, skip=skip)
    messages = [e.message for e in sup.drain_events() if "missing" in e.message]
    assert messages == ["/pph/accel: 1 samples missing before 301",
                        "/pph/accel: 12 samples missing in 12 gaps, the last before 1501"]
    assert sup.counters["missed_samples"] == 13


def test_raw_adapts_from_the_first_sample_and_identifies_only_to_measure():
    sup = NotchSupervisor(config(adaptation="raw", enabled=True, mu=1e-4))
    assert sup.state == NotchState.ADAPTING          # P = I needs nothing identified
    run(sup, coupled_gain(0.0), 100)
    assert not sup.identification.running and np.any(sup.canceller.weights != 0)
    run(sup, coupled_gain(0.0), 3200, 100)
    assert sup.status()["identification_start_sample"] == 100
    assert np.array_equal(sup.canceller.coefficients[0], np.eye(6))     # P = I stays


@pytest.mark.parametrize("at_start", [True, False], ids=["at_start_up", "switched_on"])
def test_control_that_cannot_adapt_without_auto_identify_says_why(at_start):
    sup = NotchSupervisor(config(auto_identify=False, enabled=at_start))
    if not at_start:
        run(sup, coupled_gain(0.0), 200)
        assert not [e for e in sup.drain_events() if e.level == "warn"]
        sup.apply({"enabled": True})
    warnings = [e.message for e in sup.drain_events() if e.level == "warn"]
    assert warnings == [gate.BLIND_CONTROL] and "~/identify" in warnings[0]
    run(sup, coupled_gain(0.0), 500, 200)
    assert sup.state == NotchState.ENABLED and not np.any(sup.canceller.weights)
    assert sup.status()["not_adapting"] == gate.BLIND_CONTROL           # on /diagnostics
    sup.start_identification()
    assert "not_adapting" not in sup.status()                            # asked: learning
    raw = NotchSupervisor(config(auto_identify=False, enabled=True, adaptation="raw"))
    assert not [e for e in raw.drain_events() if e.level == "warn"]     # P = I adapts
    assert "not_adapting" not in raw.status()


def test_new_tones_are_identified_and_known_tones_are_not():
    sup = NotchSupervisor(config())
    run(sup, coupled_gain(0.0), 100 + 3200)
    sup.apply({"tone_frequencies_hz": [40.0, 80.0]})
    assert sup.state == NotchState.IDENTIFYING
    assert sup.status()["identification_start_sample"] == 3300
    run(sup, coupled_gain(0.0), 3200, 3300)
    assert sup.plant_response.shape == (2, 6, 6)
    sup.apply({"tone_frequencies_hz": [80.0]})
    assert sup.state == NotchState.DISABLED         # 80 Hz is known: no new identification


def test_bad_settings_are_refused_with_a_reason():
    sup = NotchSupervisor(config())
    for changes, words in (({"tone_frequencies_hz": [40.0, 40.0]}, "duplicate"),
                           ({"tone_frequencies_hz": [600.0]}, r"in \(0, 500\) Hz"),
                           ({"tone_frequencies_hz": list(range(1, 18))}, "at most 16"),
                           ({"adaptation": "fancy"}, "adaptation = 'fancy' is not one of"),
                           ({"mu": float("nan")}, "finite")):
        with pytest.raises(ValueError, match=words):
            sup.check(changes)
    with pytest.raises(KeyError, match="not a notch setting"):
        sup.apply({"gain": 1.0})


def test_the_update_lowpass_is_set_at_start_up_only():
    """Given at construction it reaches the canceller; a later change is refused.

    The reason says why (the bound was computed with it) and nothing changes; a bad value
    is refused too.
    """
    sup = NotchSupervisor(config(update_lowpass_hz=10.0, identification="broadband"))
    assert sup.canceller.update_lowpass_hz == 10.0
    with pytest.raises(ValueError, match="set at start-up"):
        sup.check({"update_lowpass_hz": 5.0})
    with pytest.raises(ValueError, match="update_lowpass_hz = -0.5 Hz: must be -1"):
        sup.check({"update_lowpass_hz": -0.5})
    sup.apply({"update_lowpass_hz": 10.0})          # the same value: nothing to refuse
    assert sup.canceller.update_lowpass_hz == 10.0 == sup.config.update_lowpass_hz
    with pytest.raises(ValueError, match="update_lowpass_hz must be"):
        NotchSupervisor(config(update_lowpass_hz=600.0))
    for moving in ({"frequency_tracking": True}, {"reference_harmonics": [1.0]}):
        sup.check(moving)                            # moving tones take it too


def test_the_automatic_update_lowpass_is_on_for_fixed_tones_and_off_for_moving_ones():
    """``update_lowpass_hz`` -1 (the default): 10 Hz for fixed tones, 0 for moving ones.

    Chosen at start-up; a change that would need the other corner is refused with the
    reason and changes nothing.
    """
    fixed = NotchSupervisor(NotchConfig(tone_frequencies_hz=(TONE,)))
    assert fixed.config.update_lowpass_hz == -1.0 and fixed.canceller.update_lowpass_hz == 10.0
    assert fixed.status()["update_lowpass_hz"] == 10.0
    before = fixed.config
    for moving in ({"frequency_tracking": True}, {"reference_harmonics": [1.0]}):
        with pytest.raises(ValueError, match=f"{next(iter(moving))}: with update_lowpass_hz "
                                             "-1 .automatic. these tones would adapt with a "
                                             "0 Hz update low-pass, but the one in force is "
                                             "10 Hz, chosen at start-up"):
            fixed.apply(moving)
    assert fixed.config == before and fixed.canceller.update_lowpass_hz == 10.0
    tracked = NotchSupervisor(NotchConfig(tone_frequencies_hz=(TONE,), frequency_tracking=True))
    assert tracked.canceller.update_lowpass_hz == 0.0
    with pytest.raises(ValueError, match="the one in force is 0 Hz"):
        tracked.check({"frequency_tracking": False})
    tracked.check({"frequency_tracking": False, "reference_harmonics": [1.0]})   # still moving


def test_a_new_run_restarts_the_sequence_and_keeps_what_was_identified():
    sup = NotchSupervisor(config(enabled=True))
    run(sup, coupled_gain(0.0), 100 + 3200 + 2000)
    response, weights = sup.plant_response.copy(), sup.canceller.weights.copy()
    assert sup.state == NotchState.ADAPTING
    sup.reset_run(0)                                 # a restarted driver starts at 0 again
    assert sup.step(0, np.full(6, GRAVITY)) is not None
    assert sup.last_sample == 0 and sup.counters["duplicates"] == 0
    assert np.array_equal(sup.plant_response, response)
    assert np.allclose(sup.canceller.weights, weights, atol=1e-3)
    assert sup.state == NotchState.ADAPTING and sup.status()["enabled_since_sample"] == 0


def test_a_line_offset_fade_lowers_mu_to_zero_before_the_weights_freeze():
    """The line-offset fade: mu falls to 0 with the weights adapting, then they freeze.

    The fall is a raised cosine, then the output fades; the oscillators stay on their tones.
    Settings that let control try again give mu back, unless they bring a mu of their own.
    """
    sup = NotchSupervisor(config(enabled=True))
    start = 100 + 3200 + 2000
    run(sup, coupled_gain(0.0), start)
    canceller, mu = sup.canceller, sup.canceller.mu
    assert sup.state == NotchState.ADAPTING and mu > 0.0
    sup.fade_out("line off the notch: test", fade_s=0.5, mu_fall_s=1.0)
    assert sup.state == NotchState.REFUSED and sup.guard_state == "off"
    mus, gains, frozen, weights = [], [], [], []
    for n in range(start, start + 1600):
        run(sup, coupled_gain(0.0), 1, n)
        mus.append(canceller.mu)
        gains.append(canceller.output_gain)
        frozen.append(canceller.frozen)
        weights.append(canceller.weights.copy())
    mus, gains = np.array(mus), np.array(gains)
    fall = int(1.0 * FS)
    assert np.all(np.diff(mus) <= 0.0) and mus[fall // 2 - 1] == pytest.approx(mu / 2, rel=0.05)
    assert mus[fall - 1] == 0.0 and frozen[fall - 1] and not frozen[fall - 2]
    assert np.all(gains[:fall] == 1.0)                       # the output fades after the fall
    assert gains[fall + 249] == pytest.approx(0.5, abs=0.01) and gains[-1] == 0.0
    assert not np.array_equal(weights[100], weights[0])      # still adapting while mu falls
    assert np.array_equal(weights[-1], weights[fall])        # frozen after
    assert canceller.tone_frequencies_hz.tolist() == [TONE]
    assert fader.MU_RAMP_STEP_SAMPLES > 1 and len(set(mus[:fall].tolist())) > 50   # a staircase
    sup.apply({"adaptation": "decentralized"})              # control tries again: mu back
    assert canceller.mu == mu and not canceller.frozen and canceller.enabled
    sup.fade_out("line off the notch: test", fade_s=0.5, mu_fall_s=1.0)
    run(sup, coupled_gain(0.0), 300, start + 1600)
    sup.apply({"mu": mu / 4})                                 # ... with a mu of its own
    assert canceller.mu == mu / 4


def _splatter_db(command: np.ndarray, band_hz: tuple[float, float]) -> float:
    """Power of strut 1's command in ``band_hz`` over the line's power (dB), Welch 4 s."""
    f, p = signal.welch(command[:, 0], FS, window="hann", nperseg=4000)
    line = np.abs(f - TONE) < 2.0
    band = (f >= band_hz[0]) & (f < band_hz[1])
    return 10 * np.log10(p[band].sum() / p[line].sum())


def _fade_run(fade) -> tuple[np.ndarray, np.ndarray]:
    """A converged canceller, then ``fade(sup)`` 1 s into a 10 s record: commands and gains."""
    sup = NotchSupervisor(config(enabled=True))
    start = 100 + 3200 + 3000
    run(sup, coupled_gain(0.0), start)
    assert sup.state == NotchState.ADAPTING
    commands, gains = np.zeros((10000, 6)), np.zeros(10000)
    u = np.zeros(6)
    for i, n in enumerate(range(start, start + 10000)):
        if i == 1000:
            fade(sup)
        d = 0.05 * np.linspace(0.5, 1.5, 6) * np.cos(2 * np.pi * TONE * n / FS + 0.3)
        u = sup.step(n, GRAVITY + d + coupled_gain(0.0) @ u).copy()
        commands[i], gains[i] = u, sup.canceller.output_gain
    return commands, gains


def test_control_faded_out_puts_the_line_back_without_splatter():
    """The guard's fade-out (and any fade-out) keeps the line out of the bands beside it.

    It puts back the line the canceller cancelled: the command's power in the third octave
    beside it (44.7-56.2 Hz, 4.7 Hz from the 40 Hz tone) over a 10 s record holding 1 s of
    the line and the fade is at least 75 dB under the line's (measured -79.9 dB; the linear
    0.25 s fade: -34.4 dB, +23 dB over the twin in that band on the PPH).
    """
    commands, gains = _fade_run(lambda sup: sup.fade_out("test"))
    assert gains[999] == 1.0 and gains[-1] == 0.0
    assert _splatter_db(commands, (44.7, 56.2)) < -75.0


def test_switching_control_off_by_hand_fades_along_the_same_curve():
    """``enabled: false`` fades the output as the guard does: smooth, over FADE_S (1 s).

    No kink at the start (the gain still 0.99 after 50 ms, where the linear ``ramp_s`` fade
    was at 0), half way at 0.5 s, 0 at 1 s; the splatter as the guard's.
    """
    commands, gains = _fade_run(lambda sup: sup.apply({"enabled": False}))
    assert FADE_S == 1.0
    assert gains[999] == 1.0 and gains[1050] > 0.99
    assert gains[1500] == pytest.approx(0.5, abs=0.01) and gains[2000] == 0.0
    assert np.all(np.diff(gains[1000:2001]) <= 0.0)
    assert _splatter_db(commands, (44.7, 56.2)) < -75.0



def test_new_tones_during_the_analysis_stop_it_and_take_over():
    """Tones set while a broadband identification is analysed (one piece per sample).

    The analysis worked on the old tones' coefficients: finished after the change it put a
    (1, 6, 6) P on two oscillators and the node died (a README tuning run in CI). Now it
    stops, at whichever of its samples the change comes, and the new tones take over: G(f)
    known (control adapts at both) or, before the measurement, identified again.
    """
    k, broadband = coupled_gain(0.0), config(identification="broadband", enabled=True)

    def analysing(sup: NotchSupervisor) -> bool:
        return sup.identification.analysis is not None

    reference = NotchSupervisor(broadband)
    first = len(run(reference, k, 20_000, until=analysing))
    pieces = len(run(reference, k, 1000, first, until=lambda sup: not analysing(sup)))
    assert pieces >= 3 and reference.state == NotchState.ADAPTING  # held wait, Nyquist
    for offset in (0, pieces // 2, pieces - 1):
        sup = NotchSupervisor(broadband)
        n = len(run(sup, k, 20_000, until=analysing))
        run(sup, k, offset, n)
        assert analysing(sup)
        sup.apply({"tone_frequencies_hz": [40.0, 80.0]})
        assert not analysing(sup)
        run(sup, k, 500, n + offset)
        assert sup.canceller.coefficients.shape == (2, 6, 6)
        if sup.plant_response is None:
            assert sup.state == NotchState.IDENTIFYING
        else:
            assert sup.plant_response.shape == (2, 6, 6)
            assert sup.state == NotchState.ADAPTING


def test_a_broadband_identification_goes_on_for_new_tones():
    """A broadband identification's G(f) covers 0..fs/2: no new 10 s record for new tones.

    Neither while it runs nor while its analysis waits for the driver's report on held
    commands (a realtime driver).
    """
    k, broadband = coupled_gain(0.0), config(identification="broadband", enabled=True)
    for waiting in (False, True):
        sup = NotchSupervisor(broadband)
        run(sup, k, 5000)
        start = sup.status()["identification_start_sample"]
        assert sup.identification.running
        if waiting:
            sup.note_held([], 4999)                 # a realtime driver reports, then not
            n = 5000 + len(run(sup, k, 20_000, 5000,
                               until=lambda s: s.identification.analysis is not None))
            run(sup, k, 50, n)
            assert sup.identification.analysis is not None      # waits for the report
            n += 50
        else:
            n = 5000
        sup.apply({"tone_frequencies_hz": [40.0, 80.0]})
        assert sup.state == NotchState.IDENTIFYING
        if waiting:
            run(sup, k, 50, n)
            sup.note_held([], n + 49)               # the report on its last samples came
            n += 50
        run(sup, k, 12_000 - n, n)
        assert sup.status()["identification_start_sample"] == start
        assert sup.plant_response.shape == (2, 6, 6)
        assert sup.state == NotchState.ADAPTING


@pytest.mark.parametrize("changes", [{"mu": 0.0}, {"adaptation": "raw"}])
def test_a_setting_changed_while_identifying_waits_for_the_identification(changes):
    """A mu of 0 (nothing adapts) or ``raw`` set during the start-up identification.

    mu 0 once killed the analysis (the mu policy divided by it); ``raw`` stopped the
    identification as not needed and then adapted blind: on this rig P = I diverges (G's
    phase, a one-sample delay from a positive gain, is not what ``raw`` assumes), +24 dB in
    15 s with nothing to stop it. Now the identification goes on: mu 0 takes G and waits
    for a rate, and ``raw`` is refused by the bound it finds.
    """
    k = coupled_gain(0.2)
    sup = NotchSupervisor(NotchConfig().replaced({"tone_frequencies_hz": [TONE],
                                                  "identify_delay_s": 0.1}))
    run(sup, k, 3000)
    sup.apply(changes)
    n = 3000 + len(run(sup, k, 12_000, 3000, until=lambda s: not s.identification.busy))
    assert sup.plant_response is not None
    if "mu" in changes:
        assert sup.state == NotchState.ADAPTING and sup.status()["tone_mu"] == []
        sup.apply({"mu": 0.002})                     # the policy chooses now
        assert len(sup.status()["tone_mu"]) == 1
        off = NotchSupervisor(NotchConfig().replaced({"tone_frequencies_hz": [TONE],
                                                      "enabled": False}))
        on = run(sup, k, 4000, n)[-1000:]
        assert tone_rms(on) < 0.1 * tone_rms(run(off, k, 1000))
    else:
        assert sup.state == NotchState.REFUSED and "bound is 0" in sup.status()["refusal"]


def test_a_tone_change_checked_then_applied_runs_its_nyquist_limit_once(monkeypatch):
    """The node validates a change (check) and then applies it: one Nyquist limit, not two.

    Defaults (broadband identification: G(f) known), adapting; the same change applied to
    a twin without a check gives the same bound.
    """
    from hexapod_vibration.core.control import sensitivity

    def adapting() -> tuple[NotchSupervisor, int]:
        sup = NotchSupervisor(NotchConfig().replaced({"tone_frequencies_hz": [TONE],
                                                      "identify_delay_s": 0.1}))
        k = coupled_gain(0.2)
        n = len(run(sup, k, 30_000, until=lambda s: s.state == NotchState.ADAPTING))
        assert sup.state == NotchState.ADAPTING and sup.plant_frequency_response is not None
        return sup, n

    tests = []
    stable = sensitivity.closed_loop_is_stable
    monkeypatch.setattr(sensitivity, "closed_loop_is_stable",
                        lambda *a, **kw: tests.append(a[4]) or stable(*a, **kw))
    change = {"tone_frequencies_hz": [TONE, 2 * TONE]}
    twin, _ = adapting()
    tests.clear()
    twin.apply(change)
    alone = len(tests)
    sup, _ = adapting()
    tests.clear()
    sup.check(change)
    sup.apply(change)
    assert alone > 0 and len(tests) == alone
    assert sup.bound == twin.bound > 0.0


def _adapting_with_a_line_monitor() -> tuple[NotchSupervisor, int]:
    """A supervisor (mu_policy auto: a prediction) adapting 1.9 s, its line monitor ready."""
    sup = NotchSupervisor(NotchConfig().replaced(
        {"tone_frequencies_hz": (TONE,), "enabled": True, "identify_delay_s": 0.1}))
    end = 100 + 10_000 + 2000
    run(sup, coupled_gain(0.0), end)
    monitor = sup.safety.line_monitor
    assert sup.state == NotchState.ADAPTING and monitor.started and monitor.ready
    return sup, end


def test_a_long_gap_restarts_the_line_monitor_and_a_short_one_does_not():
    """Its blocks count samples (``safety.LINE_GAP_SAMPLES``); gaps of a few are common."""
    from hexapod_vibration.core.control.supervisor.safety import LINE_GAP_SAMPLES

    sup, end = _adapting_with_a_line_monitor()
    monitor = sup.safety.line_monitor
    short = frozenset(range(end, end + LINE_GAP_SAMPLES))
    run(sup, coupled_gain(0.0), 200, end, skip=short)
    assert sup.safety.line_monitor is monitor and monitor.ready
    long = frozenset(range(end + 200, end + 201 + LINE_GAP_SAMPLES))
    run(sup, coupled_gain(0.0), LINE_GAP_SAMPLES + 2, end + 200, skip=long)
    assert monitor.started and not monitor.ready        # one sample since the reset


def test_the_watchdog_s_samples_restart_the_line_monitor_and_a_forecast_s_do_not():
    """The weights re-converge after the driver's ramp back up: no reading of their turning.

    A realtime driver's reports (every 100 samples, command delay 0): a forecast stood in
    at one sample, then a run of the watchdog's.
    """
    sup, end = _adapting_with_a_line_monitor()
    monitor = sup.safety.line_monitor

    def run_reported(first: int, rows: list[tuple[int, int, int]]) -> None:
        sup.note_stand_ins([], first - 1, 0)
        run(sup, coupled_gain(0.0), 100, first)
        sup.note_stand_ins(rows, first + 99, 0)

    run_reported(end, [(end + 50, end + 50, 0)])
    run(sup, coupled_gain(0.0), 1, end + 100)           # the report's samples released
    assert monitor.ready and sup.safety.feed.stand_in_samples > 0
    run_reported(end + 101, [(end + 150, end + 160, 1)])
    run(sup, coupled_gain(0.0), 1, end + 201)
    assert sup.safety.feed.watchdog_samples > 0 and monitor.started and not monitor.ready
