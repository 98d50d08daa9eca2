"""The mu policy's choice after a setting change, made on the analysis worker meanwhile.

A change of tones or adaptation mode while G(f) is known puts a normalised P in force at
once (stable at the ``mu`` in force: the change's Nyquist limit bounds it) and leaves the
mu policy's per-tone rates and the type-2 test of sweeping tones to be made
(:meth:`RatePolicy.choose_pending`). Inline (lockstep, or no worker) they are made within
the change, as before. With an analysis worker and a loop to serve
(:attr:`WaitingJobs.serving`), :class:`BackgroundChoice` makes them one piece per sample:
the parameter service answers after the change's Nyquist limit, not after the choice too
(the choice was ~6 s of the ~11 s a realtime tone change took to answer under SCHED_FIFO
load).

Until the choice is in force the adaptation is held (P = 0: the weights, and the
cancellation of the tones kept, stay; a new tone waits). Adapting every tone at ``mu``
meanwhile is stable (the limit bounds it) but not never-worse: the policy's rates can be a
sixth of ``mu``, and a realtime run with [40] -> [40, 80] Hz adapting at ``mu`` for those
seconds rose +12 dB broadband and the guard faded control out.

Tones that may move (tracking, a reference) keep the choice within the change (the loop
served meanwhile, adaptation held too): their retuning scales P by the rates in force,
which the choice would change under it.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.analysis_jobs import JobRunner, Pieces
from hexapod_vibration.core.control.supervisor.events import EventLog
from hexapod_vibration.core.control.supervisor.rate_policy import RatePolicy


class BackgroundChoice:
    """Makes the mu policy's pending choice in pieces, one per :meth:`step` (see the module).

    Args:
        rates: the rate policy whose pending choice is made.
        canceller: the canceller whose adaptation is held until the choice is in force.
        runner: the analysis worker the jobs run on.
        events: where the wait is reported.
    """

    def __init__(self, rates: RatePolicy, canceller: AdaptiveNotchCanceller,
                 runner: JobRunner, events: EventLog) -> None:
        """Nothing running."""
        self._rates = rates
        self._canceller = canceller
        self._events = events
        self._runner = runner
        self._pieces: Pieces | None = None
        self._for: np.ndarray | None = None

    @property
    def running(self) -> bool:
        """True while a choice is being made."""
        return self._pieces is not None

    def choose_pending(self, steady: bool) -> None:
        """The pending choice: started in the background if it can be, else made now.

        ``steady``: the tones do not move (see the module). A choice in progress is
        dropped first (:meth:`cancel`).
        """
        rates = self._rates
        self.cancel()
        pending = rates.pending_choice() if rates.waits.serving else None
        if pending is None:
            rates.choose_pending()          # inline: nothing pending, or no loop to serve
            return
        tones, coefficients = pending
        self._canceller.set_coefficients(np.zeros_like(coefficients))
        self._events.add("info", "mu_policy: choosing the tones' rates on the analysis "
                                 "worker; adaptation held (weights kept) until then")
        if not steady:
            rates.waits.run(rates.choose_and_check(tones, coefficients))
            return
        self._for = coefficients
        self._pieces = Pieces(rates.choose_and_check(tones, coefficients), self._runner)

    def step(self) -> None:
        """The choice's next piece, or a wait for its job (once per loop sample)."""
        if self._pieces is not None and self._pieces.step():
            self._pieces = self._for = None

    def cancel(self) -> None:
        """Stop a choice in progress, its result dropped.

        Before the rates were chosen, their P waits for a choice again; after (the type-2
        test was running), sweeping tones are not allowed the type-2 update (untested).
        """
        if self._pieces is None:
            return
        self._pieces.close()
        rates = self._rates
        if rates.choice is None:
            if rates.unchosen is None:
                rates.unchosen = self._for
        else:
            rates.type2_max_mu = 0.0
        self._pieces = self._for = None
