"""Where each tone's line is before tracking starts: the tracker only fine-tracks from there.

The phase-locked tracker pulls a tone in only from about the canceller's own bandwidth, so
the tones are first acquired: after a broadband identification at the strongest
disturbance line it fitted within each tone's tracking bounds (:meth:`Acquisition.from_lines`),
and again when adaptation starts at the strongest line of the last second of error without
output or excitation (:meth:`Acquisition.from_record`: a drifting line has moved since).
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control.frequency_tracker import (
    ACQUISITION_RECORD_S,
    FrequencyTracker,
    acquisition_frequencies,
    strongest_lines_hz,
)
from hexapod_vibration.core.control.plant_identification import RemovedLine

ACQUISITION_SLOPE_WINDOW_HZ = 1.0
"""The halves of the acquisition record look for the line within this of where the whole
record found it (Hz): its rate of change is their difference."""


class Acquisition:
    """A ring buffer of the error without output; the lines found in it or by G(f)'s fit.

    Args:
        sample_rate_hz: loop rate fs (Hz).
        channels: number of struts C.
    """

    def __init__(self, sample_rate_hz: float, channels: int) -> None:
        """No record until :meth:`reset` asks for one."""
        self._fs = float(sample_rate_hz)
        self._channels = int(channels)
        self.record: np.ndarray | None = None
        """The last :data:`ACQUISITION_RECORD_S` of error (ring buffer), None: not kept."""
        self._count = 0
        self._broken = False

    def reset(self, keep: bool) -> None:
        """Start the record again (``keep``: tracking on), or keep none."""
        self.record = (np.zeros((int(round(ACQUISITION_RECORD_S * self._fs)), self._channels))
                       if keep else None)
        self._count = 0

    def take(self, error: np.ndarray, quiet: bool) -> None:
        """Record the error (C,) (m/s^2) of a sample without output and excitation (``quiet``).

        A quiet stretch after a loud one starts the record again; a loud sample keeps the
        record (the stretch just before control on).
        """
        if quiet:
            if self._broken:
                self._count, self._broken = 0, False
            self.record[self._count % self.record.shape[0]] = error
            self._count += 1
        else:
            self._broken = True

    def from_record(self, tracker: FrequencyTracker, present_hz: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Each tone's strongest line (Hz, NaN: none) in the record and its slope (Hz/s).

        None while the record is not full. The record's window does not resolve lines
        closer than its main lobe's half width (2 / record length): a tone with a neighbour
        that close (``present_hz``) keeps its place (``close_tones``, 39 and 40 Hz: the 1 s
        record put them at 38.70 and 40.33 Hz).
        """
        size = self.record.shape[0]
        if self._count < size:
            return None
        start = self._count % size
        record = np.concatenate([self.record[start:], self.record[:start]])
        found = strongest_lines_hz(record, self._fs, tracker.lower_hz, tracker.upper_hz)
        slope = self._slopes_hz_per_s(record, found, tracker)
        others = np.abs(found[:, None] - present_hz[None, :])
        np.fill_diagonal(others, np.inf)
        found[np.min(others, axis=1, initial=np.inf) < 2.0 / ACQUISITION_RECORD_S] = np.nan
        return found, slope

    def _slopes_hz_per_s(self, record: np.ndarray, found: np.ndarray,
                         tracker: FrequencyTracker) -> np.ndarray:
        """Each found line's rate of change (Hz/s) from the record's two halves (0: none).

        The strongest line of each half within +-:data:`ACQUISITION_SLOPE_WINDOW_HZ` of
        the whole record's; a half without it, or a tone without a line, gives 0.
        """
        half = record.shape[0] // 2
        window = ACQUISITION_SLOPE_WINDOW_HZ
        lower = np.where(np.isfinite(found), found - window, tracker.lower_hz)
        upper = np.where(np.isfinite(found), found + window, tracker.upper_hz)
        first = strongest_lines_hz(record[:half], self._fs, lower, upper)
        second = strongest_lines_hz(record[half:], self._fs, lower, upper)
        slope = (second - first) / (half / self._fs)
        return np.where(np.isfinite(slope) & np.isfinite(found), slope, 0.0)

    def from_lines(self, lines: list[RemovedLine], nominal_hz: np.ndarray,
                   range_hz: float) -> np.ndarray:
        """Each tone's strongest line (Hz, NaN: none) within its tracking bounds."""
        freqs = np.array([line.frequency_hz for line in lines], dtype=float)
        strength = np.array([float(np.linalg.norm(line.amplitude)) for line in lines])
        return acquisition_frequencies(nominal_hz, range_hz, self._fs, freqs, strength)
