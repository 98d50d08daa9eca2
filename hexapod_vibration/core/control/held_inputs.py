"""Commands the driver held instead of applying them: the input that really went in.

A realtime driver applies, at each sample, the command that answers the sample due; when it
is late it keeps the one before in force (and after ``command_timeout_samples`` its
watchdog ramps the force down to zero, and back up once commands come again). For an
identification that is a different input from the one it designed: a few held samples in a
hundred spoil G(f) (on the coupled test plant 1 % of held inputs put
the uncertainty at 138 %). The driver reports which commands it held (``/pph/notch_held``:
runs of due samples, the sample whose command stood in (-1: none) and the gain it went in
with), and:

- :class:`HeldCommands` keeps those reports for the running identification: up to which
  due sample they are complete, and the rows;
- :func:`input_difference` turns them into the difference between the applied and the
  designed excitation, per sample of the identification run (N);
- :func:`held_input_response` is the response of a G(f) to an input from rest (m/s^2):
  the identifier's model of its record (``BroadbandIdentifier._modelled``).

No ROS import.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:       # plant_identification imports this module
    from hexapod_vibration.core.control.plant_identification import BroadbandIdentifier

HELD_WAIT_SAMPLES = 500
"""Longest wait (samples) of a finished identification for the driver's report on its last
samples (reports come every 100 samples): then analysed with what came."""


HeldRow = tuple[int, int, int, float]
"""``(first due, last due, applied sample or -1, gain)``: a run of due samples whose force was
``gain`` times the command of sample ``applied`` (``/pph/notch_held``)."""

KEEP_SAMPLES = 30_000
"""Rows older than this many samples before the newest report are dropped (an identification
lasts 10 s) once more than ``KEEP_ROWS`` are kept."""
KEEP_ROWS = 1_000


class HeldCommands:
    """The driver's reports of held commands, for one run of the loop."""

    def __init__(self) -> None:
        """No report yet."""
        self.clear()

    def clear(self) -> None:
        """Forget every report (a new run of the loop)."""
        self.reported = False
        """True once a report came: the driver reports (a realtime driver)."""
        self.covered = -1
        """The last due sample the reports are complete up to (-1: none)."""
        self._rows: list[HeldRow] = []

    def add(self, rows: Sequence[HeldRow], covered: int) -> None:
        """A report: rows ``(first due, last due, applied sample or -1, gain)``, to ``covered``."""
        self.reported = True
        self.covered = max(self.covered, int(covered))
        self._rows.extend((int(a), int(b), int(c), float(g)) for a, b, c, g in rows)
        if len(self._rows) > KEEP_ROWS:
            self.forget_before(self.covered - KEEP_SAMPLES)

    def covers(self, last_sample: int) -> bool:
        """The reports are complete up to ``last_sample`` (or there are none to wait for)."""
        return not self.reported or self.covered >= last_sample

    def forget_before(self, sample: int) -> None:
        """Drop the rows that end before ``sample`` (an identification starting there)."""
        self._rows = [row for row in self._rows if row[1] >= sample]

    def rows(self, first: int, last: int) -> list[HeldRow]:
        """The rows that overlap the due samples ``first..last``."""
        return [row for row in self._rows if row[1] >= first and row[0] <= last]

    def correct(self, identifier: BroadbandIdentifier, first: int
                ) -> Generator[None, None, str | None]:
        """Wait for the report on the record's last sample; correct ``identifier`` for the rows.

        The record started at sample ``first``. At most ``HELD_WAIT_SAMPLES`` samples, one
        per ``yield``; without reports (lockstep, a driver that does not report) at once.
        Returns the one-line account of the correction, None when nothing was held.
        """
        total = identifier.total_samples
        last = first + total - 1
        for _ in range(HELD_WAIT_SAMPLES):
            if self.covers(last):
                break
            yield
        rows = self.rows(first, last)
        if not rows:
            return None
        held = sum(min(b, last) - max(a, first) + 1 for a, b, _, _ in rows)
        identifier.correct_for_held_inputs(
            input_difference(rows, first, identifier.design.period_table(), total))
        complete = "" if self.covers(last) else " (the driver's report on its last " \
            "samples did not come)"
        return (f"identification: the driver held {held} of its {total} commands; G "
                f"corrected for them{complete}")


def input_difference(rows: Sequence[HeldRow], start: int, table: np.ndarray,
                     total: int) -> np.ndarray:
    """Applied minus designed excitation (total, C) (N) of a run that started at ``start``.

    The run's command for sample ``start + k`` was ``table[k % P]``; a held row gives the
    samples whose command was replaced by ``gain`` times that of its ``applied`` sample
    (zero force for -1, and for a sample before the run, whose command held no excitation).
    """
    period = table.shape[0]
    du = np.zeros((total, table.shape[1]))
    for first, last, applied, gain in rows:
        k = np.arange(max(first, start), min(last, start + total - 1) + 1) - start
        if k.size == 0:
            continue
        du[k] = -table[k % period]
        if applied >= start:
            du[k] += gain * table[(applied - start) % period]
    return du


def held_input_response(at: Callable[[np.ndarray], np.ndarray], difference: np.ndarray,
                        sample_rate_hz: float) -> np.ndarray:
    """The response (N, C) (m/s^2) of G to ``difference`` (N, C) (N), from rest.

    ``at(f)`` gives G (F, C, C) at frequencies f (Hz) in [0, fs/2]; the convolution runs in
    the frequency domain on a grid padded by one second, for the plant's memory.
    """
    n = difference.shape[0]
    nfft = 1 << int(np.ceil(np.log2(n + int(sample_rate_hz))))
    frequencies = np.fft.rfftfreq(nfft, 1.0 / sample_rate_hz)
    spectrum = np.fft.rfft(difference, nfft, axis=0)
    response = np.einsum("fij,fj->fi", at(frequencies), spectrum)
    return np.fft.irfft(response, nfft, axis=0)[:n]
