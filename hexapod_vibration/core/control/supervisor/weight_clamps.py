"""Anti-windup's clamps: counted, said once a second, and whether they hold control.

The canceller clips each strut's weights after every update so that they never add up to
more than ``weight_limit_n`` (:meth:`~hexapod_vibration.core.control.notch_weights.
NotchWeights.limit_weights`: the actuators' rating). Every clamped sample is counted
(``weight_clamps`` on ``/diagnostics``) and said at most once a second.

A limit below what the disturbance needs clamps on nearly every sample under control: the
largest tones sit at the limit, the others keep what they need. That can be a useful partial
result (Table 1 at 3 N: 40 Hz 22 dB down, 80 Hz 56 dB), but a weight clipped every sample
is a nonlinearity: narrow spurious lines appear (0.3 N, 23-27 s against the twin: bins at
159, 205.5, 121.25 and 66 Hz 17-25 dB over it), and at 0.3 N the divergence guard faded
control out on the 158 Hz third octave (+2.5 dB); at 1 N the same band stayed 0.97-1.39 dB
over its level without control in the 10 s windows from control-on, under the guard's
threshold (core loop against the twin, ``single_tone_harmonic``). So when control fades
out while the weights are held at the limit (clamped on at least
:data:`HELD_CLAMP_FRACTION` of the samples of the last :data:`HELD_BLOCKS` judged guard
blocks), the reason says so (:meth:`WeightClamps.note`): the fix is the limit, not the rate.
"""

from __future__ import annotations

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.events import EventLog

HELD_CLAMP_FRACTION = 0.9
"""Share of a judged block's samples the clamp must have acted on for the block to count as
held at the limit (Table 1 at 0.3 N: 0.998 of the samples under control)."""
HELD_BLOCKS = 4
"""Judged guard blocks in a row (0.25 s each: 1 s) held at the limit for the weights to
count as held (:attr:`WeightClamps.held`). Table 1 at 0.3 N: clamped from 38 ms after
control-on, faded out by the guard 2.5 s after it."""


class WeightClamps:
    """Says the weights' clamps and knows whether they hold control at the limit.

    Args:
        settings: the settings in force (``weight_limit_n``, fs).
        canceller: the canceller whose clamps are read (``clamped_samples``).
        events: where a clamp is said (at most once a second).
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 events: EventLog) -> None:
        """No clamp counted, no block judged."""
        self._settings, self._canceller, self._events = settings, canceller, events
        self._last_event = -10**9
        self._held_blocks = 0
        self._fraction = 0.0
        self._last_block: tuple[int, int] | None = None     # (last sample, clamps then)

    @property
    def count(self) -> int:
        """Samples on which the clamp acted (``weight_clamps``: the canceller's count)."""
        return self._canceller.clamped_samples

    def clamped(self, n: int) -> None:
        """The clamp acted at sample ``n``: say so at most once a second."""
        if n - self._last_event >= self._settings.fs:
            self._last_event = n
            self._events.add("warn", f"weights clamped to the actuator rating "
                                     f"{self._settings.config.weight_limit_n:g} N (anti-windup)")

    def judged(self, n: int, block_samples: int) -> None:
        """A guard block of ``block_samples`` samples ending at sample ``n`` was judged.

        Its share of clamped samples is the canceller's clamps since the block before; a
        block that does not follow the one before (a dropped block) starts the count again.
        """
        clamps = self._canceller.clamped_samples
        last, self._last_block = self._last_block, (n, clamps)
        if last is None or n - last[0] != block_samples:
            self._held_blocks = 0
            return
        self._fraction = (clamps - last[1]) / block_samples
        held = self._fraction >= HELD_CLAMP_FRACTION
        self._held_blocks = self._held_blocks + 1 if held else 0

    @property
    def held(self) -> bool:
        """True while the last :data:`HELD_BLOCKS` judged blocks were held at the limit."""
        return self._held_blocks >= HELD_BLOCKS

    def note(self) -> str:
        """What a fade-out's reason adds while the weights are held at the limit ("" if not)."""
        if not self.held:
            return ""
        limit = self._settings.config.weight_limit_n
        return (f"; the weights were held at weight_limit_n {limit:g} N (clamped on "
                f"{100.0 * self._fraction:.0f} % of the samples): the tones need more force "
                "than it allows, raise it up to the actuators' rating")

    def restart(self) -> None:
        """Control starts again (new settings, a new identification): count afresh."""
        self._held_blocks = 0
        self._last_block = None
