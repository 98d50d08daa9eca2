"""The mu policy: manual warns, auto keeps the predicted rise within the limit."""

import sys
from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.core.control import adaptation as ad
from hexapod_vibration.core.control import mu_policy
from hexapod_vibration.core.control import sensitivity as sen

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from linear_plants import FS, frequency_response, resonance_bank  # noqa: E402


def _far_field_plant():
    """A lightly damped resonance at 20 Hz under tones at 39/40 Hz: the far rise scales with mu.

    Normalised at the tones the weight loop has no phase error, so the rise beside the
    notches is small; the canceller's tail meets the resonance (gain 10x the tones',
    opposite phase) and amplifies it in proportion to the rate.
    """
    plant = resonance_bank(20.0, 0.02, 1.0)
    return plant, (lambda f: frequency_response(plant, f))


def _rise(g, tones, p, rates):
    return sen.predict_sensitivity(g, tones, FS, p, rates).largest_rise("sigma_max")[0]


def test_manual_keeps_mu_and_warns_when_the_prediction_breaks_the_limit():
    _, g = _far_field_plant()
    tones = [39.0, 40.0]
    p = ad.normalized_coefficients(g(tones), "centralized")
    high = mu_policy.choose_tone_rates(g, tones, FS, p, 0.0008, "manual", 1.0)
    assert np.all(high.tone_mu == 0.0008)
    assert high.predicted_rise_db > 1.0
    assert "predicts a rise" in high.warning and "max_rise_db=1" in high.warning
    low = mu_policy.choose_tone_rates(g, tones, FS, p, 1e-5, "manual", 1.0)
    assert low.warning is None and low.within_limit


def test_auto_takes_the_largest_rates_within_the_limit():
    _, g = _far_field_plant()
    tones = [39.0, 40.0, 80.0]
    p = ad.normalized_coefficients(g(tones), "centralized")
    choice = mu_policy.choose_tone_rates(g, tones, FS, p, 0.0008, "auto", 1.0)
    assert choice.warning is None
    assert choice.predicted_rise_db <= 1.0 + 1e-9
    assert np.all(choice.tone_mu <= 0.0008) and np.any(choice.tone_mu < 0.0008)
    assert abs(_rise(g, tones, p, choice.tone_mu) - choice.predicted_rise_db) < 1e-9
    for t in range(3):                        # no tone can go 5 % faster (or is at mu)
        faster = choice.tone_mu.copy()
        faster[t] = min(0.0008, 1.05 * faster[t])
        if faster[t] > choice.tone_mu[t]:
            assert _rise(g, tones, p, faster) > 1.0


def test_auto_says_so_when_no_rate_helps():
    """A coefficient 60 deg off gives +6 dB beside the notch at any rate."""
    plant = resonance_bank(300.0, 0.5, 1.0)
    g = lambda f: frequency_response(plant, f)  # noqa: E731
    p = ad.normalized_coefficients(g([40.0]), "centralized") * np.exp(1j * np.pi / 3)
    choice = mu_policy.choose_tone_rates(g, [40.0], FS, p, 0.002, "auto", 3.0)
    assert np.all(choice.tone_mu == 0.002)
    assert "remain at any rate" in choice.warning


def test_auto_still_bounds_the_far_rise_when_the_notch_floor_breaks_the_limit():
    """P 30 deg off: 1.25 dB beside the notches at any rate, 8.7 dB at 20 Hz at full mu.

    The limit (0.5 dB) is out of reach; the rates are lowered until the far rise is
    within the floor plus FLOOR_MARGIN_DB instead of staying at mu.
    """
    _, g = _far_field_plant()
    tones = [39.0, 40.0]
    p = ad.normalized_coefficients(g(tones), "centralized") * np.exp(1j * np.pi / 6)
    assert _rise(g, tones, p, np.full(2, 0.0008)) > 8.0
    floor = _rise(g, tones, p, np.full(2, 0.0008 * mu_policy.SMALLEST_SCALE))
    choice = mu_policy.choose_tone_rates(g, tones, FS, p, 0.0008, "auto", 0.5)
    assert np.all(choice.tone_mu < 0.0008)
    assert floor < choice.predicted_rise_db <= floor + mu_policy.FLOOR_MARGIN_DB + 1e-9
    assert "remain at any rate" in choice.warning and "rates bounded" in choice.warning


def test_unstable_loop_is_reported():
    plant = resonance_bank(60.0, 0.02, 1.0)
    g = lambda f: frequency_response(plant, f)  # noqa: E731
    p = ad.normalized_coefficients(g([40.0]), "decentralized")
    exact = ad.exact_mu_bound(plant, [40.0], FS, p)
    manual = mu_policy.choose_tone_rates(g, [40.0], FS, p, 1.5 * exact, "manual")
    assert manual.predicted_rise_db == float("inf") and "unstable" in manual.warning
    auto = mu_policy.choose_tone_rates(g, [40.0], FS, p, 1.5 * exact, "auto")
    assert auto.tone_mu[0] < exact and auto.within_limit


def test_bad_settings_are_refused():
    _, g = _far_field_plant()
    p = ad.normalized_coefficients(g([40.0]), "centralized")
    with pytest.raises(ValueError, match="mu_policy"):
        mu_policy.choose_tone_rates(g, [40.0], FS, p, 0.002, "fast")
    with pytest.raises(ValueError, match="max_rise_db"):
        mu_policy.choose_tone_rates(g, [40.0], FS, p, 0.002, "auto", 0.0)
    with pytest.raises(ValueError, match="metric"):
        mu_policy.choose_tone_rates(g, [40.0], FS, p, 0.002, "auto", metric="mean")
    with pytest.raises(ValueError, match="output_weights"):
        mu_policy.choose_tone_rates(g, [40.0], FS, p, 0.002, "auto", metric="output")
