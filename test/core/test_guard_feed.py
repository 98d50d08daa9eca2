"""The guard's feed: straight on without reports, held for them and stand-ins left out with.

The referenced guard of test_divergence_guard (a 40 Hz line and noise, 16 blocks); a
realtime driver's reports come every 100 samples, complete to ``covered``, with the command
delay d = 2 (due sample j is applied at j + 2).
"""

from __future__ import annotations

import numpy as np
import pytest

from hexapod_vibration.core.control.divergence_guard import DivergenceGuard
from hexapod_vibration.core.control.guard_feed import (
    KICK_SAMPLES,
    MAX_HELD_SAMPLES,
    WATCHDOG_SETTLE_SAMPLES,
    GuardFeed,
)

FS, TONE, BLOCK, DELAY = 1000.0, 40.0, 250, 2
START = 4000                 # the first judged sample


def _signal(rng, samples, start, tone_amp=0.05, noise=0.002):
    n = np.arange(start, start + samples)
    mix = np.linspace(0.5, 1.5, 6)
    line = tone_amp * mix[None, :] * np.cos(2 * np.pi * TONE * n / FS + 0.3)[:, None]
    return line + noise * rng.standard_normal((samples, 6))


@pytest.fixture
def feed_and_rng():
    rng = np.random.default_rng(5)
    guard = DivergenceGuard(6, FS, [TONE], margin_db=1.0)
    for n, e in enumerate(_signal(rng, START, 0)):
        guard.step(e, True, False, index=n)
    assert guard.reference_blocks == 16
    return GuardFeed(guard), rng


def _kicked(rng) -> np.ndarray:
    """Judged samples with a 0.2 m/s^2 one-sample kick mid-block in two blocks in a row."""
    x = _signal(rng, 8 * BLOCK, START)
    x[3 * BLOCK + 125] += 0.2
    x[4 * BLOCK + 125] += 0.2
    return x


def _judge(feed: GuardFeed, x: np.ndarray, stand_ins: list[int] | None) -> list:
    """The verdicts (with their sample) of x judged from START.

    With ``stand_ins`` (the stand-ins' applied samples) a report comes every 100 samples.
    """
    verdicts = []
    for k, e in enumerate(x):
        n = START + k
        if stand_ins is not None and n % 100 == 0:
            covered = n - 1 - DELAY                        # due samples settled so far
            rows = [(s - DELAY, s - DELAY, 0) for s in stand_ins if n - 100 <= s < n]
            feed.note(rows, covered, DELAY)
        verdicts += [(sample, v) for v, sample in feed.step(e, False, True, n)]
    return verdicts


def test_without_reports_the_feed_is_the_guard(feed_and_rng):
    feed, rng = feed_and_rng
    verdicts = _judge(feed, _kicked(rng), None)
    acted = [(n, v) for n, v in verdicts if v.action]
    assert acted and acted[0][0] == START + 5 * BLOCK - 1       # the second kicked block
    assert acted[0][1].band.startswith("1/3 octave")
    assert feed.guard.blocks_with_stand_ins == 0


def test_reported_stand_ins_leave_their_blocks_out(feed_and_rng):
    feed, rng = feed_and_rng
    kicks = [START + 3 * BLOCK + 125, START + 4 * BLOCK + 125]
    verdicts = _judge(feed, _kicked(rng), kicks)
    assert all(v.action is None for _, v in verdicts)
    assert feed.guard.blocks_with_stand_ins == 2
    assert feed.stand_in_samples == 2 * (1 + KICK_SAMPLES)
    assert len(verdicts) == 8 - 2 - 1       # the last block is not covered yet: held


def test_a_real_rise_is_still_caught_one_report_later(feed_and_rng):
    feed, rng = feed_and_rng
    worse = _signal(rng, 3 * BLOCK, START, tone_amp=0.05 * 10 ** (6 / 20))     # +6 dB
    verdicts = [(n, v) for n, v in _judge(feed, worse, []) if v.action]
    assert verdicts[0][1].action == "lower_mu" and verdicts[0][0] == START + BLOCK - 1


def test_samples_not_covered_go_on_unmarked_after_the_longest_hold(feed_and_rng):
    feed, rng = feed_and_rng
    feed.note([], START - 1, DELAY)                 # one report, then none
    x = _signal(rng, MAX_HELD_SAMPLES + 2 * BLOCK, START)
    released = [n for k, e in enumerate(x)
                for _, n in feed.step(e, False, True, START + k)]
    assert released == [START + BLOCK - 1, START + 2 * BLOCK - 1]     # the newest held
    assert feed.held_samples == MAX_HELD_SAMPLES
    feed.restart()
    assert not feed.reported and feed.held_samples == 0


def test_a_watchdog_run_leaves_the_platform_s_settling_out_and_then_judges_again(feed_and_rng):
    """After the watchdog's ramp the next WATCHDOG_SETTLE_SAMPLES' blocks are left out.

    A lost pointing force rings for seconds; a rise after them is caught.
    """
    feed, rng = feed_and_rng
    settle_blocks = WATCHDOG_SETTLE_SAMPLES // BLOCK
    blocks = 2 + settle_blocks + 4
    x = _signal(rng, blocks * BLOCK, START)
    ringing = slice(BLOCK + 50, (2 + settle_blocks) * BLOCK)        # the platform's answer
    x[ringing] += 0.05 * rng.standard_normal((ringing.stop - ringing.start, 6))
    worse = slice((2 + settle_blocks + 1) * BLOCK, None)            # control's own doing
    x[worse] *= 10 ** (6 / 20)
    watchdog = (START + BLOCK - DELAY, START + BLOCK + 40 - DELAY)  # due samples of the run
    verdicts = []
    for k, e in enumerate(x):
        n = START + k
        if n % 100 == 0:
            rows = [(*watchdog, 1)] if n - 100 <= watchdog[1] < n else []
            feed.note(rows, n - 1 - DELAY, DELAY)
        verdicts += [(sample, v) for v, sample in feed.step(e, False, True, n)]
    acted = [(n, v.action) for n, v in verdicts if v.action]
    assert acted and acted[0][0] >= START + (2 + settle_blocks + 1) * BLOCK, acted
    assert feed.watchdog_samples == 41 + WATCHDOG_SETTLE_SAMPLES
    assert feed.stand_in_samples == feed.watchdog_samples
