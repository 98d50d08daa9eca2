"""Held commands in a broadband identification: the reports, the input, the correction.

On the coupled test plant of ``test_plant_identification``: the driver applies an older
command (or zero force) in place of the designed one at a few samples; told which, the
identifier subtracts their response and measures G as if they had not been held.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.core.control.held_inputs import (
    HeldCommands,
    HeldRow,
    held_input_response,
    input_difference,
)
from hexapod_vibration.core.control.plant_identification import BroadbandIdentifier
from hexapod_vibration.parameter_specs import PPH_DRIVER

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from linear_plants import (  # noqa: E402
    FS,
    frequency_response,
    late_notch_rig,
    resonance_bank,
)

FADE_SAMPLES = PPH_DRIVER["command_fade_samples"].default
"""The driver's watchdog ramp: the 20 ms stalls below fall along it (rows with gains)."""
FREQUENCIES_HZ = np.arange(20.0, 300.0, 0.37)


def _coupled_plant(seed=1):
    a, b, c = resonance_bank([30.0, 55.0, 90.0], 0.1, 1.0)
    mix = np.eye(3) + 0.3 * np.random.default_rng(seed).normal(size=(3, 3))
    return a, b @ mix, c


def _held_rows(n: int, fraction: float, burst: int, start: int) -> list[HeldRow]:
    """Runs of ``burst`` held samples (sample indices from ``start``).

    The command before the run stands in, zero force from the sixth sample of a run (the
    driver's watchdog with a ramp of 0 samples).
    """
    rows = []
    for first in np.flatnonzero(np.random.default_rng(7).random(n) < fraction / burst):
        last = min(first + burst - 1, n - 1)
        first, last = int(first) + start, int(last) + start
        rows.append((first, min(last, first + 4), first - 1, 1.0))
        if last > first + 4:
            rows.append((first + 5, last, -1, 0.0))
    return rows


def _identify(rows, start):
    """The identification on the plant with ``rows`` held; (identifier, plant)."""
    plant = _coupled_plant()
    ident = BroadbandIdentifier(3, FS, period_s=4.0, settle_s=1.0, periods=2)
    n = int(round(ident.duration_s * FS))
    table = ident.design.period_table()
    applied = table[np.arange(n) % table.shape[0]] + input_difference(rows, start, table, n)
    dist = 1e-3 * np.random.default_rng(2).normal(size=(n, 3))
    a, b, c = plant
    x = np.zeros(a.shape[0])
    for k in range(n):
        ident.step(c @ x + dist[k])
        x = a @ x + b @ applied[k]
    return ident, plant


def _errors(ident, plant):
    exact = frequency_response(plant, FREQUENCIES_HZ)
    result = ident.result()
    got = result.at(FREQUENCIES_HZ)
    error = np.linalg.norm(got - exact, axis=(1, 2)) / np.linalg.norm(exact, axis=(1, 2))
    return float(np.median(error)), float(np.max(result.uncertainty_at([40.0, 80.0])))


@pytest.mark.parametrize(("fraction", "burst"), [(0.01, 1), (0.03, 20)])
def test_told_which_commands_were_held_the_identifier_measures_g_again(fraction, burst):
    start = 5_000                                   # sample index of the run's first sample
    rows = _held_rows(9_000, fraction, burst, start)   # the run: 1 + 2 x 4 s
    ident, plant = _identify(rows, start)
    n = int(round(ident.duration_s * FS))
    raw_median, raw_uncertainty = _errors(ident, plant)
    assert raw_uncertainty > 0.1                    # uncorrected: refused by the supervisor
    ident.correct_for_held_inputs(input_difference(rows, start, ident.design.period_table(), n))
    median, uncertainty = _errors(ident, plant)
    print(f"held {fraction:.0%} in runs of {burst}: median error {raw_median:.3f} -> "
          f"{median:.4f}, uncertainty at 40/80 Hz {raw_uncertainty:.3f} -> {uncertainty:.4f}")
    assert uncertainty < 0.05 and median < 0.02


def test_a_correction_that_does_not_help_is_not_kept():
    """Told of held commands that were not held, the identifier keeps its record."""
    ident, plant = _identify([], 0)
    before = _errors(ident, plant)
    n = int(round(ident.duration_s * FS))
    wrong = _held_rows(n, 0.01, 1, 0)
    ident.correct_for_held_inputs(input_difference(wrong, 0, ident.design.period_table(), n))
    assert _errors(ident, plant) == before


def test_the_input_difference_of_held_rows():
    table = np.arange(12.0).reshape(4, 3)           # a period of 4 samples, 3 channels
    rows = [(101, 102, 100, 1.0), (104, 104, -1, 0.0), (99, 100, 95, 1.0), (105, 105, 101, 0.25)]
    du = input_difference(rows, 100, table, 6)
    expected = np.zeros((6, 3))
    expected[1] = table[0] - table[1]               # sample 101: the command of 100
    expected[2] = table[0] - table[2]
    expected[4] = -table[0]                         # sample 104: zero force
    expected[5] = 0.25 * table[1] - table[1]        # sample 105: a quarter of that of 101
    expected[0] = -table[0]                         # sample 100: a command before the run
    np.testing.assert_array_equal(du, expected)


def test_the_response_to_an_impulse_is_the_impulse_response():
    plant = _coupled_plant()
    a, b, c = plant
    impulse = np.zeros((400, 3))
    impulse[10, 1] = 1.0
    expected, x = np.zeros((400, 3)), np.zeros(a.shape[0])
    for k in range(400):
        expected[k] = c @ x
        x = a @ x + b @ impulse[k]
    got = held_input_response(lambda f: frequency_response(plant, f), impulse, FS)
    np.testing.assert_allclose(got, expected, atol=1e-6 * np.max(np.abs(expected)))


def test_the_reports_cover_what_they_say():
    held = HeldCommands()
    assert held.covers(10_000)                      # no reports: nothing to wait for
    held.add([(5, 7, 4, 1.0)], covered=99)
    held.add([(150, 150, -1, 0.0)], covered=199)
    assert held.covers(199) and not held.covers(200)
    assert held.rows(0, 100) == [(5, 7, 4, 1.0)]
    held.forget_before(100)
    assert held.rows(0, 1_000) == [(150, 150, -1, 0.0)]


def _supervised_identification(report: bool):
    """A notch supervisor identifying a 6-channel coupled plant.

    Its driver holds 2 % of its commands (single samples and runs of 20), and reports them
    (or not).
    """
    from hexapod_vibration.core.loop.held_log import HeldLog

    (a, b, c), supervisor, arbiter, late, rng = late_notch_rig(14_000)
    log = HeldLog()
    x = np.zeros(a.shape[0])
    t = np.arange(14_000) / FS
    shaker = 0.02 * np.sin(2 * np.pi * 40.0 * t)[:, None] + 1e-4 * rng.normal(size=(14_000, 6))
    for n in range(14_000):
        command = supervisor.step(n, c @ x + shaker[n])
        if not late[n]:
            arbiter.offer("notch", command.copy(), n, 1, 0.0)
        forces, _ = arbiter.close_sample(False, 5, FADE_SAMPLES)
        notch = arbiter.streams["notch"]
        log.note(arbiter.due, notch.applied, notch.fade.gain)
        if report and n % 100 == 0 and log.covered >= 0:
            supervisor.note_held(log.drain(), log.covered)
        x = a @ x + b @ forces["notch"]
        arbiter.advance()
    events = [e.message for e in supervisor.drain_events()]
    return supervisor, int(np.count_nonzero(late[:11_000])), events


def test_a_supervisor_told_of_held_commands_identifies_the_plant():
    supervisor, held, events = _supervised_identification(report=True)
    print(f"{held} of the identification's samples held", *events, sep="\n  ")
    assert any("G corrected for them" in e for e in events), events
    assert supervisor.state in ("adapting", "enabled"), events
    assert not any("identification failed" in e for e in events), events


def test_without_the_reports_the_held_commands_spoil_the_identification():
    supervisor, _, events = _supervised_identification(report=False)
    assert supervisor.state == "refused", events
    assert any("identification failed" in e for e in events), events


def test_samples_observed_but_not_acted_on_stay_in_the_identification_record():
    """A loop behind skips samples for newer ones: observed, they are not missing."""
    from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor

    a, b, c = resonance_bank([22.0, 35.0, 48.0, 61.0, 95.0, 140.0], 0.05, 1.0)
    missing = {}
    for observe in (False, True):
        supervisor = NotchSupervisor(NotchConfig().replaced(
            {"tone_frequencies_hz": [40.0], "identify_delay_s": 0.0}))
        x, u = np.zeros(a.shape[0]), np.zeros(6)
        for n in range(9_999):                  # the 10 s run's last sample not yet taken
            accel = c @ x
            if n % 97 == 50:                     # behind: skipped for the next one
                if observe:
                    supervisor.observe(n, accel)
            else:
                u = supervisor.step(n, accel).copy()
            x = a @ x + b @ u
        missing[observe] = supervisor.identification.identifier.missing
    assert missing == {False: 82, True: 0}      # measured: past the 2 s of settling
