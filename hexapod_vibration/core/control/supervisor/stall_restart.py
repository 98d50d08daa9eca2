"""An identification that a stall of the loop disturbed starts again once the platform settled.

A realtime driver marks the runs of its watchdog in its stand-in reports (``/pph/stand_ins``:
a controller silent past ``command_timeout_samples`` and its forecast, the stream's force
ramped to zero and back, :mod:`~hexapod_vibration.core.loop.stale_fade`). When the pointing
controller is the one silent, the platform loses ~35 N per strut and rings for seconds: a
broadband identification whose record holds that measures the stall, not the plant
(``single_tone_harmonic`` in realtime, both controllers stopped 350 ms in its record: 60 %
uncertainty at the tones, refused, control never engaged). Leaving the samples out is no
remedy: with the platform's settling they are a third of the record.

:class:`StallRestart` says whether such a run falls in the record, and when the record may
start again: at the end of the settling the guard leaves out too
(:data:`~hexapod_vibration.core.control.guard_feed.WATCHDOG_SETTLE_SAMPLES`). A loop that
stalls again and again is not identified on: after :data:`MAX_STALL_RESTARTS` restarts in a
row the identification is refused, with the reason. No ROS import.
"""

from __future__ import annotations

MAX_STALL_RESTARTS = 3
"""Restarts of one identification for stalls of the loop before it is refused."""

STALL_REFUSAL = (f"identification refused: the loop stalled in its record "
                 f"{MAX_STALL_RESTARTS + 1} times (the driver's watchdog ramped a controller's "
                 "force); control stays off (~/identify to measure again)")


class StallRestart:
    """When a stalled identification starts again, and how many times it did."""

    def __init__(self) -> None:
        """Nothing waiting."""
        self.resume_at = -1
        """The sample the identification starts again at (-1: none waiting)."""
        self.restarts = 0
        """Restarts for stalls since the identification was first started."""

    @property
    def waiting(self) -> bool:
        """True while an identification waits for the platform to settle."""
        return self.resume_at >= 0

    @staticmethod
    def disturbs(first: int, settled: int, start_sample: int, record_samples: int) -> bool:
        """The disturbed samples overlap the record of ``record_samples`` from ``start_sample``.

        Disturbed: ``first..settled-1``, a watchdog run and the platform's settling.
        """
        return first < start_sample + record_samples and settled > start_sample

    def schedule(self, settled: int) -> bool:
        """Start again at sample ``settled``; False (nothing scheduled) past the limit."""
        if self.restarts >= MAX_STALL_RESTARTS:
            self.clear()
            return False
        self.restarts += 1
        self.resume_at = max(self.resume_at, int(settled))
        return True

    def warning(self, first: int) -> str:
        """What a restart scheduled for a watchdog's run from sample ``first`` says."""
        return (f"identification disturbed: the driver's watchdog ramped a controller's force "
                f"at sample {first} (a controller stalled or started late); it starts again "
                f"at sample {self.resume_at}, once the platform settled (restart "
                f"{self.restarts} of at most {MAX_STALL_RESTARTS})")

    def postpone(self, settled: int) -> None:
        """Disturbed again while waiting: start at ``settled`` if later (no restart counted)."""
        self.resume_at = max(self.resume_at, int(settled))

    def due(self, index: int) -> bool:
        """True at the first sample at or past the one to start again at (then not waiting)."""
        if self.resume_at < 0 or index < self.resume_at:
            return False
        self.resume_at = -1
        return True

    def clear(self) -> None:
        """A new identification (not a restart) or none: nothing waiting, no restart counted."""
        self.resume_at = -1
        self.restarts = 0
