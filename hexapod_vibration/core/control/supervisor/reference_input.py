"""The tachometer: reference frequency values (Hz) by loop sample, fresh or stale.

With ``reference_harmonics`` set, tone k runs at ``order_k x reference`` while the last
value is at most ``reference_timeout_s`` old (extrapolated along the slope of the last two
values to the middle of the block the tones are set for); a value that is not finite and
> 0 is ignored (and reported once until a usable one comes).
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from hexapod_vibration.core.control.supervisor.events import EventLog


class ReferenceState(StrEnum):
    """Where the reference stands (``reference`` on /diagnostics)."""

    UNUSED = "unused"
    """No ``reference_harmonics``: the tones do not follow a reference."""
    WAITING = "waiting"
    """No value yet."""
    FOLLOWING = "following"
    """The last value is fresh: the tones follow it."""
    STALE = "stale"
    """The last value is older than ``reference_timeout_s``."""


class ReferenceInput:
    """The last reference value, its slope, and the orders the tones run at.

    Args:
        sample_rate_hz: loop rate fs (Hz).
        events: where ignored values are reported.
    """

    def __init__(self, sample_rate_hz: float, events: EventLog) -> None:
        """No value yet, no orders (unused)."""
        self._fs = float(sample_rate_hz)
        self._events = events
        self.hz = float("nan")
        """The last value (Hz)."""
        self.index = -1
        """The loop sample it belongs to (-1: none yet)."""
        self.slope = 0.0
        """Its rate of change (Hz per sample), from the last two values."""
        self.state = ReferenceState.UNUSED
        self.orders = np.zeros(0)
        """Each tone's order of the reference (empty: unused)."""
        self.timeout_samples = 0.0
        self._ignoring = False

    def configure(self, orders: tuple[float, ...], timeout_s: float) -> None:
        """The tones' orders and the timeout (s); waiting for a value if there are orders."""
        self.orders = np.asarray(orders, dtype=float)
        self.timeout_samples = timeout_s * self._fs
        self.state = ReferenceState.WAITING if self.orders.size else ReferenceState.UNUSED

    def set(self, frequency_hz: float, index: int) -> None:
        """Store a value (Hz) of sample ``index``; its slope from the previous one."""
        try:
            value = float(frequency_hz)
        except (TypeError, ValueError):
            value = float("nan")
        if not np.isfinite(value) or value <= 0.0:
            if not self._ignoring:         # once until a usable value comes (no flood)
                self._events.add("warn", f"reference frequency {frequency_hz!r} ignored: "
                                         "not a finite frequency > 0 Hz")
            self._ignoring = True
            return
        self._ignoring = False
        if index > self.index >= 0 and np.isfinite(self.hz):
            self.slope = (value - self.hz) / (index - self.index)
        self.hz, self.index = value, int(index)

    def state_at(self, index: int) -> ReferenceState:
        """The state at sample ``index`` (following while the last value is fresh)."""
        if self.index >= 0 and index - self.index <= self.timeout_samples:
            return ReferenceState.FOLLOWING
        return ReferenceState.STALE if self.index >= 0 else ReferenceState.WAITING

    def fundamentals_hz(self, index: int, block: int, top_order: float) -> np.ndarray:
        """Order x the reference at the middle of the block from ``index`` (Hz).

        Each within (0, fs/2) with its top harmonic ``top_order`` below fs/2 too.
        """
        ahead = index - self.index + 0.5 * block
        reference = self.hz + self.slope * ahead
        nyquist = 0.5 * self._fs
        top = self.orders * top_order
        return np.clip(self.orders * reference, 1e-3 * nyquist,
                       0.999 * nyquist * self.orders / top)

    @property
    def rates_hz_per_s(self) -> np.ndarray:
        """Each fundamental's rate of change (Hz/s) on the reference: order x its slope."""
        return self.slope * self._fs * self.orders
