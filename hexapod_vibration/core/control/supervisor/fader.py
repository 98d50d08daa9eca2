"""The output's fade-out: the weights freeze and the output fades to 0, after mu falls.

A fade that follows a line off the notch first lowers mu to 0 over ``mu_fall_s`` (raised
cosine, set every :data:`MU_RAMP_STEP_SAMPLES`) with the weights still adapting: weights
that follow a line turn at its offset, and frozen at once they would stop turning, the
output's frequency jumping back to the oscillator's (a kink of its phase, a 1/df^2 skirt);
with mu falling they slow down and shrink smoothly. Then they freeze and the output fades
along a curve without a kink (:func:`~hexapod_vibration.core.control.notch.smooth_fade_gain`:
a linear fade of a cancelled line splatters it over the bands beside it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

MU_RAMP_STEP_SAMPLES = 10
"""The falling mu is set every this many samples (each setting rescales P: a few array
operations)."""


@dataclass
class _MuFall:
    """A fade under way: mu falling to 0 before the weights freeze."""

    mu: float
    """mu when the fall started (restored if control is tried again)."""
    samples: int
    """Length of the fall (samples)."""
    fade_samples: int
    """The output's fade once the weights froze (samples)."""
    done: int = 0
    """Samples of the fall so far."""
    last_mu: float = float("nan")
    """The last mu the fall set: another one in force means someone else set it."""


class OutputFader:
    """Fades the canceller's output out, with mu falling first where asked.

    Args:
        canceller: the canceller faded out.
        sample_rate_hz: loop rate fs (Hz).
    """

    def __init__(self, canceller: AdaptiveNotchCanceller, sample_rate_hz: float) -> None:
        """No fade under way."""
        self._canceller = canceller
        self._fs = float(sample_rate_hz)
        self._fall: _MuFall | None = None
        self.falling = False
        """True while mu falls (:meth:`step` has work to do)."""

    def fade_out(self, fade_s: float, mu_fall_s: float = 0.0) -> None:
        """Freeze the weights and fade the output to 0 over ``fade_s`` (s).

        With ``mu_fall_s`` > 0 (s) and the weights adapting, mu first falls to 0 over that
        time (:meth:`step`), and the weights freeze only then.
        """
        canceller = self._canceller
        fade = int(round(fade_s * self._fs))
        if (mu_fall_s > 0.0 and canceller.enabled and not canceller.frozen
                and canceller.mu > 0.0):
            self._fall = _MuFall(canceller.mu, max(int(round(mu_fall_s * self._fs)), 1),
                                 fade, last_mu=canceller.mu)
            self.falling = True
        else:
            canceller.set_frozen(True)
            canceller.set_enabled(False, fade, smooth=True)

    def step(self) -> None:
        """One sample of a mu fall: a raised cosine to 0, then freeze and fade the output."""
        fall = self._fall
        if fall is None or fall.done >= fall.samples:
            return
        fall.done += 1
        if fall.done % MU_RAMP_STEP_SAMPLES and fall.done < fall.samples:
            return
        x = min(fall.done / fall.samples, 1.0)
        fall.last_mu = fall.mu * 0.5 * (1.0 + float(np.cos(np.pi * x)))
        self._canceller.set_mu(fall.last_mu)
        if fall.done >= fall.samples:
            self.falling = False
            self._canceller.set_frozen(True)
            self._canceller.set_enabled(False, fall.fade_samples, smooth=True)

    def end(self) -> None:
        """Forget a mu fall; give mu back unless someone else set one since."""
        fall, self._fall = self._fall, None
        self.falling = False
        if fall is not None and self._canceller.mu == fall.last_mu:
            self._canceller.set_mu(fall.mu)
