"""Figures: each one only where it means something, and the ranges of their axes."""

from __future__ import annotations

import numpy as np
import pytest
from bag_factory import G0, frequencies_cdr, notch_status, struts_from_z, tone, write_bag

from hexapod_vibration.analysis import plots
from hexapod_vibration.analysis.bag_analysis import analyze_bag
from hexapod_vibration.analysis.run_record import RunRecord
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.paths import config_path

MODEL = load_model_config(config_path("pph_model.yaml"))
END, ON = 12_000, 6_000


def _bag(tmp_path, name, notch_hz, true_hz, harmonics_of_hz=0.0):
    """A bag of 40 and 80 Hz tones, the notch on from ``ON`` when it has tones.

    Frequency topics: the true frequency ``true_hz(sample)``, the notch's tones as estimates.
    """
    z = G0 + tone(-31.0, 40.0, END) + tone(-50.0, 80.0, END, 0.4)
    if notch_hz:
        n = np.arange(END)
        z[ON:] -= (1 - np.exp(-(n[ON:] - ON) / 500.0)) * tone(-31.0, 40.0, END)[ON:]
    statuses = [(s, notch_status(s, "adapting" if s >= ON else "disabled", notch_hz,
                                 ON if s >= ON else -1, (500, 1500)))
                for s in range(0, END, 1000)] if notch_hz else []
    topics = {"/pph/disturbance_frequencies": [(s, frequencies_cdr([true_hz(s), 80.0], s))
                                               for s in range(0, END, 100)]}
    if notch_hz:
        topics["/pph/notch_frequencies"] = [(s, frequencies_cdr(notch_hz, s))
                                            for s in range(0, END, 100)]
    record = RunRecord(name, [40.0, 80.0], notch_hz, 4.0, END, ON if notch_hz else -1,
                       500 if notch_hz else -1, 1000 if notch_hz else 0,
                       harmonics_of_hz=harmonics_of_hz)
    return write_bag(tmp_path / name, struts_from_z(z), statuses=statuses,
                     run_record=record.to_json(), topics=topics)


def _figures(tmp_path, bag):
    out = tmp_path / f"{bag.name}_out"
    result = analyze_bag(bag, out, MODEL)
    names = sorted(p.name for p in out.glob("*.png"))
    assert names == sorted(n for n in result.details["plots"] if n.endswith(".png"))
    return names


def test_fixed_tones_have_no_frequencies_and_no_plant_response_figure(tmp_path):
    """Two fixed tones (a fundamental fitted to their mix, flat frequency lines: nothing)."""
    bag = _bag(tmp_path, "fixed", [40.0, 80.0], lambda s: 40.0)
    assert _figures(tmp_path, bag) == ["convergence.png", "spectra.png"]


def test_a_moving_tone_has_its_frequencies_figure(tmp_path):
    bag = _bag(tmp_path, "drift", [40.0], lambda s: 40.0 + 0.5 * np.sin(2 * np.pi * s / 8000))
    assert _figures(tmp_path, bag) == ["convergence.png", "frequencies.png", "spectra.png"]


def test_the_plant_response_figure_is_for_the_distortion_analysis(tmp_path):
    bag = _bag(tmp_path, "fig4", [], lambda s: 40.0, harmonics_of_hz=40.0)
    assert _figures(tmp_path, bag) == ["plant_response.png", "spectra.png"]


@pytest.mark.parametrize("tracks, moving", [
    ({}, False),
    ({"truth": (np.arange(3), np.array([[39.0, 40.0], [39.0, 40.0], [39.0, 40.0]]))}, False),
    ({"truth": (np.arange(3), np.array([[40.0], [40.005], [np.nan]]))}, False),
    ({"estimate": (np.arange(3), np.array([[40.0], [40.0], [40.4]]))}, True),
    ({"tachometer": (np.arange(2), np.array([30.0, 50.0]))}, True),
])
def test_frequencies_move(tracks, moving):
    assert plots.frequencies_move(tracks) is moving


@pytest.mark.parametrize("curves, limits", [
    # a deep measured notch (-88 dB) and the prediction's exact zero: clipped at -40 dB
    ([np.array([-88.0, -3.0, 0.0, 7.2]), np.array([-190.0, 0.5])], (-40.0, 10.0)),
    # a quiet loop: the never-worse line still shows
    ([np.array([-12.3, -1.0, 0.4, 1.2])], (-15.0, 5.0)),
    ([np.array([-2.0, 0.5])], (-5.0, 5.0)),
    # a broken loop: at most +20 dB
    ([np.array([-30.0, 0.0, 45.0] + [1.0] * 2000)], (-30.0, 5.0)),
    ([np.array([-30.0] + [45.0] * 10)], (-30.0, 20.0)),
    ([np.array([np.nan, np.inf])], (-40.0, 5.0)),
    ([], (-40.0, 5.0)),
])
def test_sensitivity_axis_spans_what_was_measured(curves, limits):
    assert plots.sensitivity_limits_db(curves) == limits


def test_pointing_axes_fit_the_quiet_run():
    t = np.arange(0.05, 40.0, 0.1)
    quiet = plots.quiet_samples(t, [(1.0, 11.0)])
    assert not quiet[t < 11.0].any() and quiet[t >= 11.0].all()
    pose = np.where((t > 3.0) & (t < 9.0), 500.0, np.sin(t))[:, None]   # identification
    lo, hi = plots.pose_limits(pose, quiet)
    assert -1.4 < lo < -1.0 and 1.0 < hi < 1.4
    # an identification over the whole run: fit all of it rather than nothing
    assert plots.quiet_samples(t, [(0.0, 40.0)]).all()
