"""The watchdog's ramp: a stale stream's force falls smoothly to zero and rises back.

The driver's watchdog takes a command stream whose last command is more than
``command_timeout_samples`` old (and whose forecast does not cover the sample due) to zero
force (:mod:`~hexapod_vibration.core.loop.command_arbiter`). Dropping it in one sample is a
step: the pointing controller holds ~35 N per strut, and a 345-sample stall of both
controllers (a ROS process joining over shared memory, a VM pause) stepped the applied
force 35 -> 0 N and back, which lifted the broadband spectrum 12-21 dB, made the divergence
guard fade control out and spoiled a running identification (``docs/performance.md``).

:class:`StaleFade` is one stream's gain (0..1) on its force: while the stream is stale the
gain falls to zero over ``ramp_samples`` samples along
:func:`~hexapod_vibration.core.control.notch.smooth_fade_gain` (no kink at either end) on
the command held; when the stream commands again it rises back the same way on the new
commands; a stall shorter than the ramp turns back where it is. ``ramp_samples`` 0 is the
step (zero force at once, full force at once). No ROS import.
"""

from __future__ import annotations

from hexapod_vibration.core.control.notch import smooth_fade_gain


class StaleFade:
    """The gain (0..1) of one command stream's force, after the watchdog."""

    def __init__(self) -> None:
        """Full gain: a stream is applied as commanded until it goes stale."""
        self.progress = 1.0
        """Where the ramp is (0: zero force, 1: full force)."""
        self.gain = 1.0
        """The gain of the sample stepped last."""

    def step(self, stale: bool, ramp_samples: int) -> float:
        """The gain at the next sample: one sample down the ramp if ``stale``, else up.

        Args:
            stale: The watchdog's verdict on the stream at this sample.
            ramp_samples: Samples of a whole fall or rise (>= 0; 0: a step).
        """
        step = 1.0 / ramp_samples if ramp_samples > 0 else 1.0
        progress = self.progress
        if stale:
            progress -= step
        elif progress < 1.0:
            progress += step
        else:
            return 1.0                              # the usual case: one compare
        # whole ramps in whole samples: no rounding residue left at either end
        progress = 0.0 if progress < 0.5 * step else 1.0 if progress > 1.0 - 0.5 * step \
            else progress
        self.progress = progress
        self.gain = smooth_fade_gain(progress) if 0.0 < progress < 1.0 else progress
        return self.gain

    @property
    def full(self) -> bool:
        """The stream's force is applied as commanded (no ramp under way, not stale)."""
        return self.progress >= 1.0
