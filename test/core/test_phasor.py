"""Tests of the rotating phasor bank that replaces cos/sin per sample in both controllers."""

from fractions import Fraction

import numpy as np
import pytest

from hexapod_vibration.core.control.phasor import RESYNC_SAMPLES, TWO_PI, PhasorBank

FS = 1000
# exactly representable rationals, so the exact phase grid can be computed in integers
FREQS = [Fraction(40), Fraction(80), Fraction(123456, 1000), Fraction(4999, 10)]


def exact_phasors(n_samples, freqs=FREQS, fs=FS):
    """e^{j 2 pi f n / fs} with the phase reduced exactly (rational arithmetic)."""
    n = np.arange(n_samples)
    cols = []
    for f in freqs:
        num, den = (f / fs).numerator, (f / fs).denominator
        cycles = (n * num % den) / den                  # exact fraction of a cycle
        cols.append(np.exp(1j * TWO_PI * cycles))
    return np.stack(cols, axis=1)


def test_phasor_tracks_its_phase_grid_within_1e_12_over_a_long_run():
    n_samples = 200_000                                # ~780 re-synchronisations
    dphi = TWO_PI * np.array([float(f) for f in FREQS]) / FS
    bank = PhasorBank(dphi)
    z = np.empty((n_samples, len(FREQS)), dtype=complex)
    phases = np.empty((n_samples, len(FREQS)))
    for n in range(n_samples):
        z[n] = bank.z
        phases[n] = bank.phases_rad
        bank.rotate()
    # against cos/sin of its own phase accumulator: rounding never accumulates
    assert np.max(np.abs(z - np.exp(1j * phases))) < 1e-12
    assert np.max(np.abs(np.abs(z) - 1.0)) < 1e-13
    # against the exact grid 2 pi f n / fs: only the rounding of dphi itself (a fixed
    # bias of <= 1 ulp per sample) remains, no random walk
    assert np.max(np.abs(z - exact_phasors(n_samples))) < 1e-10


def test_advance_lands_on_the_same_phasors_as_rotating():
    dphi = TWO_PI * np.array([40.0, 97.3]) / FS
    amps = np.array([0.5, 2.0])
    rotated = PhasorBank(dphi, phases_rad=[1.0, 6.0], amplitudes=amps)
    skipped = PhasorBank(dphi, phases_rad=[1.0, 6.0], amplitudes=amps)
    for _ in range(3 * RESYNC_SAMPLES + 17):
        rotated.rotate()
    for _ in range(5):
        skipped.rotate()
    skipped.advance(2 * RESYNC_SAMPLES)
    for _ in range(RESYNC_SAMPLES + 12):
        skipped.rotate()
    np.testing.assert_allclose(skipped.phases_rad, rotated.phases_rad, rtol=0, atol=1e-12)
    np.testing.assert_allclose(skipped.z, rotated.z, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.abs(rotated.z), amps, rtol=1e-13)


def test_single_tone_bank_and_bad_resync():
    bank = PhasorBank(np.array([TWO_PI * 0.1]))
    for _ in range(10):
        bank.rotate()
    assert bank.z.shape == (1,) and bank.z[0] == pytest.approx(1.0, abs=1e-13)
    with pytest.raises(ValueError):
        PhasorBank(np.array([0.1]), resync_samples=0)
