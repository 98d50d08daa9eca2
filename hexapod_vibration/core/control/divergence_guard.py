"""Never worse than off: watch the error under control against its level before control.

:class:`DivergenceGuard` is pure bookkeeping on the error the canceller sees (the six
DC-blocked accelerations, m/s^2). It cuts the error into blocks of ``block_s`` (0.25 s)
and, from a Hann-windowed FFT of each block, takes the power (summed over the channels) in

- one band per controlled tone, ``f_t +- band_half_width_hz`` (4 Hz: the band a 1 %
  frequency error or a +-1 Hz drift stays in), and
- the broadband error, ``BROADBAND_LOW_HZ`` (8 Hz) .. fs/2, and
- every one-third-octave band from ``THIRD_OCTAVE_LOW_HZ`` (50 Hz: narrower bands hold
  fewer than three of the block's 4 Hz bins) to fs/2, without the bins within the tones'
  bands and their window's main lobe (a converging tone is no rise): a harmonic the nonlinear plant
  makes of a line the canceller moves (the 80 Hz band of ``drift``) is a band too. Below
  50 Hz off the tones (the loop's resonances at 17.7 and 22.5 Hz, where the waterbed
  rise is) the bound is ``mu_policy``'s prediction, accurate there to 0.3 dB.

While control is off and nothing is injected (no identification running) the blocks build
the *reference*: the uncontrolled level of every band (mean power) and its block-to-block
scatter (dB). While control is on each block is judged against it:

- fast: one block above ``reference + margin + max(3 sigma, FAST_EXTRA_MIN_DB)`` (a
  runaway: unstable rate, wound-up weights) is a divergence, seen at the end of the block
  in which it happens (<= 0.25 s, well within the 0.5 s allowed); in a third octave off
  the tones, two judged blocks in a row (<= 0.5 s): what control does there (a harmonic,
  a resonance) lasts, while one block's rise is a transient. In realtime a command stood
  in for by a forecast is a one-sample step of 0.02-0.1 N, which lifted the 100-400 Hz
  third octaves of one block by 10-20 dB: of 13 realtime runs of ``single_tone_harmonic``
  whose guard saw every sample, 9 faded control out on such kicks (7 on one block, 2 on
  the slow mean), the same kind of kick as without control (the pointing controller's
  stand-ins, reconstructed from the bags);
- slow: the exponential mean over ``SLOW_BLOCKS`` blocks (2 s) above ``reference + margin
  + 3 sigma sqrt(v)`` (a steady excess of a few dB: a canceller that is stable but wrong,
  e.g. tuned 0.4 Hz off the line) is a divergence too; ``v`` is the variance of the mean
  it holds (:func:`slow_mean_variance`): started from one block, its first blocks are
  held to one block's scatter, not to a settled mean's. A block enters the mean at most at
  the fast threshold (a transient +20 dB block alone lifted the mean by 11 dB for seconds).

The guard decides, the supervisor acts (:class:`GuardVerdict`). The order of the actions
(:data:`ACTIONS`), one step per divergence:

1. ``lower_mu``: ``mu`` is divided by ``MU_DIVISOR``, the weights kept. A rate too high
   for the loop (the identified bound was optimistic or the plant changed) is cured by a
   lower one, which then unwinds the weights smoothly, and the benefit of control is
   kept. No weight is set back: a jump of the output splatters over every band (measured
   on ``drift``: +25 dB in 44.7-56.2 Hz for 2 s after a rollback to older weights), and
   freezing alone leaves weights tuned to a tone the disturbance has left beating
   against it. The fast detector then waits ``GRACE_BLOCKS`` blocks. Only for a tone's
   band or the broadband: a band off the tones that rises (a harmonic the nonlinear plant
   makes of a line the canceller moves) says the model is wrong, not the rate, and goes
   straight to 2.
2. ``fade_out``: adaptation stops and the output fades to 0 over
   :data:`~hexapod_vibration.core.control.notch.FADE_S` along a curve without a kink
   (:func:`~hexapod_vibration.core.control.notch.smooth_fade_gain`): a canceller whose
   model of the disturbance is wrong (frequency mismatch or drift, a plant response that
   no longer holds) diverges at any rate; off is the level it must not exceed. Control
   stays off until the settings change or a new identification succeeds.

Anti-windup (weights never above what the actuators deliver) is the supervisor's per-sample
clamp (:meth:`~hexapod_vibration.core.control.notch.AdaptiveNotchCanceller.limit_weights`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.control.guard_bands import GuardBands
from hexapod_vibration.core.control.guard_blocks import ErrorBlocks

DEFAULT_BLOCK_S = 0.25
DEFAULT_BAND_HALF_WIDTH_HZ = 4.0
FAST_EXTRA_MIN_DB = 2.0
SLOW_BLOCKS = 8
MIN_REFERENCE_BLOCKS = 4
OCTAVE_REFERENCE_BLOCKS = 16
DEFAULT_SCATTER_DB = 1.0
"""Block-to-block scatter assumed until MIN_REFERENCE_BLOCKS reference blocks exist (dB)."""
MU_DIVISOR = 4.0
GRACE_BLOCKS = 2
"""After an action the fast detector waits this many blocks (0.5 s); the slow one keeps
watching."""
ACTIONS = ("lower_mu", "fade_out")


def slow_mean_variance(blocks: int) -> float:
    """Variance of the slow detector's mean after ``blocks`` blocks, in one block's units.

    The exponential mean (weight ``a = 1 / SLOW_BLOCKS``) starts from one block:
    ``q + a^2 (1 - q) / (1 - (1 - a)^2)`` with ``q = (1 - a)^(2 (blocks - 1))``; 1 after one
    block, ``a / (2 - a)`` settled, and never below ``1 / SLOW_BLOCKS`` (the settled
    threshold's). Judged as a settled mean from its first block, the slow detector faded
    control out on the first block after 4 and 5 of 72 starts of judging on the
    uncontrolled twins of ``mismatch_tracking`` with the shaker at 41.0 Hz (two seed sets),
    always on a third octave; with this, none.
    """
    a = 1.0 / SLOW_BLOCKS
    q = (1.0 - a) ** (2 * (max(int(blocks), 1) - 1))
    return max(q + a * a * (1.0 - q) / (1.0 - (1.0 - a) ** 2), 1.0 / SLOW_BLOCKS)


class SlowMean:
    """The slow detector's exponential mean of the bands' block powers (weight 1/SLOW_BLOCKS)."""

    def __init__(self) -> None:
        """Empty: the next block starts it."""
        self.power: np.ndarray | None = None
        self.blocks = 0

    def add(self, power: np.ndarray) -> np.ndarray:
        """Fold in one block's band powers; the mean (a new array on the first block)."""
        alpha = 1.0 / SLOW_BLOCKS
        self.power = (power.copy() if self.power is None
                      else (1.0 - alpha) * self.power + alpha * power)
        self.blocks += 1
        return self.power

    def variance(self) -> float:
        """Variance of the mean in one block's units (:func:`slow_mean_variance`)."""
        return slow_mean_variance(self.blocks)


class ConsecutiveRises:
    """Bands over their threshold in two judged blocks in a row (the off-tone octaves')."""

    def __init__(self) -> None:
        """No judged block before."""
        self._before: np.ndarray | None = None

    def confirmed(self, over: np.ndarray) -> np.ndarray:
        """The bands ``over`` (bool) now that were over in the block judged before too."""
        before, self._before = self._before, over.copy()
        return over & before if before is not None else np.zeros_like(over)

    def reset(self) -> None:
        """The last block was not judged (or an action was taken): start again."""
        self._before = None


GUARD_DISABLED = "disabled"
GUARD_REFERENCING = "referencing"
GUARD_WATCHING = "watching"
GUARD_BACKED_OFF = "backed_off"
GUARD_OFF = "off"


@dataclass(frozen=True)
class GuardVerdict:
    """What the guard found at the end of a block while control was on.

    Attributes:
        action: ``None`` (all bands within their thresholds), or the action to take now
            (one of :data:`ACTIONS`).
        band: the band that diverged (e.g. ``tone 40 Hz`` or ``broadband``), or None.
        rise_db: its level above the reference (dB).
        threshold_db: the rise that counts as divergence for it (dB).
        detector: ``fast`` (one block) or ``slow`` (the exponential mean), or None.
    """

    action: str | None
    band: str | None = None
    rise_db: float = 0.0
    threshold_db: float = 0.0
    detector: str | None = None

    @property
    def text(self) -> str:
        """One line for the log."""
        if self.action is None:
            return "all bands within their level without control"
        return (f"{self.band} {self.rise_db:+.1f} dB over its level without control "
                f"(threshold {self.threshold_db:.1f} dB, {self.detector}): {self.action}")


class DivergenceGuard:
    """Block-wise band levels of the error, a reference without control, verdicts with it.

    Args:
        channels: number of error channels C.
        sample_rate_hz: loop rate fs (Hz).
        tone_frequencies_hz: the controlled tones (Hz).
        margin_db: rise over the reference that counts as worse (dB, > 0).
        block_s: block length (s).
        band_half_width_hz: half width of each tone's band (Hz).
    """

    def __init__(self, channels: int, sample_rate_hz: float,
                 tone_frequencies_hz: Sequence[float], margin_db: float = 1.0,
                 block_s: float = DEFAULT_BLOCK_S,
                 band_half_width_hz: float = DEFAULT_BAND_HALF_WIDTH_HZ) -> None:
        """Allocate the block buffer; no reference yet."""
        if not np.isfinite(margin_db) or margin_db <= 0.0:
            raise ValueError(f"guard_margin_db must be finite and > 0 dB, got {margin_db!r}")
        self.fs = float(sample_rate_hz)
        self.channels = int(channels)
        self.margin_db = float(margin_db)
        self.block = int(round(block_s * self.fs))
        self.half_width_hz = float(band_half_width_hz)
        self._blocks = ErrorBlocks(self.channels, self.block)
        self.set_tones(tone_frequencies_hz)
        self.action_count = 0
        self._grace = 0

    # ------------------------------------------------------------------ bands
    def set_tones(self, tone_frequencies_hz: Sequence[float]) -> None:
        """Bands for a new tone set; the reference and the judging start again."""
        self.tones_hz = [float(f) for f in tone_frequencies_hz]
        tones = np.asarray(self.tones_hz, dtype=float)
        self._bands = GuardBands(self.block, self.fs, self.half_width_hz, tones)
        self.band_names = self._bands.names
        self._masks, self._n_main = self._bands.masks, self._bands.main
        self._following = tones.copy()
        self._cancelled = np.zeros(tones.size)
        self._moved = False
        self.reset_reference()

    def follow_tones(self, tone_frequencies_hz: np.ndarray) -> None:
        """The tones moved (tracking, a tachometer): their bands follow; the reference stays.

        From the first move on, each tone's band is judged around where its oscillator
        runs now against the reference level of the band around where it ran in each
        reference block (the tone's level without control, wherever it was), and the
        third-octave bands leave out the bins near the present tones. While a tone is more
        than ``band_half_width_hz`` from where it was when the reference was taken (a
        spin-up), the third-octave bands are not judged (their reference holds another
        disturbance: :attr:`moved_away`); the tones' bands and the broadband are. The
        third octaves are then judged by the slow detector only: retuning the oscillators
        every few samples splatters single blocks a few dB over the noise of a band far
        from the tones (measured: +3.9 dB in one 0.25 s block of 224-282 Hz on
        ``mismatch`` tracked, +1.7 dB over its second), while a runaway shows in the
        tones' bands and the broadband at once and a steady rise (a harmonic the
        nonlinear plant makes) in the slow mean. A tone set that never moves is judged
        exactly as without this (``set_tones``' bands).
        """
        tones = np.asarray(tone_frequencies_hz, dtype=float)
        if tones.shape != self._following.shape:
            return
        if not self._moved and np.array_equal(tones, self._following):
            return
        self._moved = True
        self._following = tones.copy()

    def set_cancelled(self, amplitude: np.ndarray) -> None:
        """The canceller's output at each tone as error, (T, C) phasors (m/s^2): ``G W``.

        While the tones are away from where the reference was taken (a spin-up: the
        disturbance there is louder or softer than in the reference), each tone's band
        counts as no worse than off up to the power this output makes in it: the
        disturbance a converged canceller cancels is as large as its output.
        """
        a = np.asarray(amplitude)
        self._cancelled = (np.sum(np.abs(a) ** 2, axis=1)
                           * (self.block * np.sum(self._blocks.window ** 2) / 4.0))

    @property
    def following(self) -> bool:
        """True once the tones moved: their bands follow them (:meth:`follow_tones`)."""
        return self._moved

    @property
    def moved_away(self) -> bool:
        """True while a tone is more than a band's half width from its reference place."""
        if not self._moved or not self._ref_tones:
            return False
        return bool(np.max(np.abs(self._following - self._ref_tones[-1]), initial=0.0)
                    > self.half_width_hz)

    def reset_reference(self) -> None:
        """Forget the reference (new tones, new identification)."""
        nb = len(self.band_names)
        self._ref_sum = np.zeros(nb)
        self._ref_db = []
        self._ref_bins: list[np.ndarray] = []         # per reference block (F,) powers
        self._ref_tones: list[np.ndarray] = []        # and where the tones were
        self._ref_tone_power: list[np.ndarray] = []   # their bands' power there (T,)
        self._slow = SlowMean()
        self._octave_rises = ConsecutiveRises()
        self.last_levels_db = np.full(nb, np.nan)

    @property
    def reference_blocks(self) -> int:
        """Number of blocks in the reference."""
        return len(self._ref_db)

    @property
    def blocks_with_gaps(self) -> int:
        """Blocks dropped (neither reference nor judged) for missing samples."""
        return self._blocks.with_gaps

    @property
    def blocks_with_stand_ins(self) -> int:
        """Blocks dropped (neither reference nor judged) for a stand-in disturbed sample."""
        return self._blocks.with_stand_ins

    @property
    def has_reference(self) -> bool:
        """True once at least one reference block was taken."""
        return self.reference_blocks > 0

    def scatter_db(self, ref_db: np.ndarray | None = None) -> np.ndarray:
        """Block-to-block scatter of each band's reference level (dB).

        ``ref_db``: (R, B) the reference blocks' band levels (dB); None: the bands of
        ``set_tones``.
        """
        if self.reference_blocks < MIN_REFERENCE_BLOCKS:
            return np.full(len(self.band_names), DEFAULT_SCATTER_DB)
        return np.std(np.array(self._ref_db) if ref_db is None else ref_db, axis=0, ddof=1)

    def thresholds_db(self, ref_db: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(fast, slow) rise over the reference (dB) that counts as divergence, per band.

        Three standard deviations of the judged level (one block, or the slow mean of the
        blocks judged so far: :func:`slow_mean_variance`) and of the reference's own mean
        (``reference_blocks`` blocks) over the margin; the
        one-third-octave bands are judged (finite thresholds) only once the reference
        holds ``OCTAVE_REFERENCE_BLOCKS`` blocks: with fewer, ten noise bands would give
        false alarms.
        """
        sigma = self.scatter_db(ref_db)
        ref = 1.0 / max(self.reference_blocks, 1)
        fast = self.margin_db + np.maximum(3.0 * sigma * np.sqrt(1.0 + ref), FAST_EXTRA_MIN_DB)
        slow = self.margin_db + 3.0 * sigma * np.sqrt(self._slow.variance()
                                                      + ref)
        if self.reference_blocks < OCTAVE_REFERENCE_BLOCKS:
            fast[self._n_main:] = slow[self._n_main:] = np.inf
        return fast, slow

    # ------------------------------------------------------------------ per sample
    def step(self, error: np.ndarray, recording: bool, judging: bool,
             index: int | None = None, stood_in: bool = False) -> GuardVerdict | None:
        """Take one sample of the error (C,) (m/s^2); a verdict at the end of a judged block.

        Args:
            error: the DC-blocked error of this sample.
            recording: control is off and nothing is injected: the block may go into the
                reference.
            judging: control is on: the block is judged.
            index: the sample's index (None: the one after the last).
            stood_in: a stand-in the driver reported disturbed the sample.

        A block counts for the reference (or is judged) only if every one of its samples
        was recording (judging); a block that mixes the two, with samples missing or a
        stand-in disturbed one, is dropped
        (:class:`~hexapod_vibration.core.control.guard_blocks.ErrorBlocks`).
        """
        if (block := self._blocks.add(error, recording, judging, index, stood_in)) is None:
            return None
        bins, power = block.bins, self._masks @ block.bins
        if block.recording:
            self._ref_sum += power
            self._ref_db.append(10.0 * np.log10(np.maximum(power, 1e-300)))
            self._ref_bins.append(bins)
            self._ref_tones.append(self._following.copy())
            self._ref_tone_power.append(self._bands.tone_masks(self._following) @ bins)
            return None
        if block.judging and self.has_reference:
            if self._moved:
                return self._judge(*self._following_levels(bins))
            return self._judge(power)
        self._octave_rises.reset()
        return None

    def _following_levels(self, bins: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Block power, reference power, reference blocks' dB and judged bands, moved tones.

        See :meth:`follow_tones`: the tones' bands around the present tones against each
        reference block's band around its own tones; the other bands with the present
        tones' bins left out, on both.
        """
        tones = self._following
        masks, judged = self._bands.masks_for(tones)
        ref_bins = np.array(self._ref_bins)                              # (R, F)
        ref_blocks = ref_bins @ masks.T                                  # (R, B)
        t = tones.size
        ref_blocks[:, :t] = np.array(self._ref_tone_power)     # each at its own tones
        if self.moved_away:
            judged[self._n_main:] = False
            # the tone's level without control where it is now is at least what the
            # canceller cancels there (its output through the plant, |G W|)
            ref_blocks[:, :t] = np.maximum(ref_blocks[:, :t], self._cancelled[None, :t])
        return masks @ bins, ref_blocks.mean(axis=0), 10.0 * np.log10(
            np.maximum(ref_blocks, 1e-300)), judged

    def _judge(self, power: np.ndarray, ref: np.ndarray | None = None,
               ref_db: np.ndarray | None = None,
               judged: np.ndarray | None = None) -> GuardVerdict:
        if ref is None:
            ref = self._ref_sum / self.reference_blocks
        level = 10.0 * np.log10(np.maximum(power, 1e-300) / np.maximum(ref, 1e-300))
        self.last_levels_db = level
        fast_th, slow_th = self.thresholds_db(ref_db)
        if judged is not None:         # following moving tones (see follow_tones)
            fast_th[~judged] = slow_th[~judged] = np.inf
            fast_th[self._n_main:] = np.inf
        # A block over the fast threshold is the fast detector's: into the slow mean at that
        # threshold, so one transient cannot hold the 2 s mean up for seconds.
        cap, finite = np.full(power.shape, np.inf), np.isfinite(fast_th)
        cap[finite] = np.broadcast_to(ref, power.shape)[finite] * 10.0 ** (fast_th[finite] / 10)
        mean = self._slow.add(np.minimum(power, cap))
        slow = 10.0 * np.log10(np.maximum(mean, 1e-300) / np.maximum(ref, 1e-300))
        fast_over = level > fast_th
        fast_over[self._n_main:] = self._octave_rises.confirmed(fast_over[self._n_main:])
        detectors = [("fast", level, fast_th, fast_over), ("slow", slow, slow_th, slow > slow_th)]
        if self._grace > 0:
            self._grace -= 1
            detectors = detectors[1:]
        for detector, rise, th, over in detectors:
            over = np.flatnonzero(over)
            if over.size:
                b = int(over[np.argmax(rise[over] - th[over])])
                action = ACTIONS[min(self.action_count, len(ACTIONS) - 1)]
                if b >= self._n_main:          # off the tones: a wrong model, not a rate
                    action = ACTIONS[-1]
                self.action_count += 1
                self._slow = SlowMean()                # judge the next state afresh
                self._octave_rises.reset()
                self._grace = GRACE_BLOCKS
                return GuardVerdict(action, self._band_name(b), float(rise[b]),
                                    float(th[b]), detector)
        return GuardVerdict(None)

    def _band_name(self, b: int) -> str:
        """Band ``b``'s name; a tone's band that follows its tone says where it is now."""
        if self._moved and b < self._n_main - 1:
            return f"tone {self.tones_hz[b]:g} Hz (at {self._following[b]:.2f} Hz)"
        return self.band_names[b]

    def within_margin(self) -> bool:
        """True if the tones' bands and the broadband were within reference + margin.

        The last judged block's; the narrow bands' noise would say no half the time.
        """
        return bool(np.all(~(self.last_levels_db[:self._n_main] > self.margin_db)))

    def restart(self) -> None:
        """Control starts again from scratch (new settings): the action sequence restarts."""
        self.action_count = 0
        self._slow = SlowMean()
        self._octave_rises.reset()
        self._grace = 0
