"""The loop's contract without ROS: rates, sizes, array labels, status names.

Every ``/pph/*`` message is a ``std_msgs/Float64MultiArray`` of six values in strut order
1..6 with ``layout.dim[0] = ("strut", 6, 6)``. The driver and the controllers add
``layout.dim[1] = ("sample:<n>", 1, 1)`` carrying the loop's sample index ``n`` in band, and
``layout.dim[2] = ("run:<id>", 1, 1)`` carrying the identity of the driver's run (a random
number drawn at the driver's start): the array keeps its six values (shape (6, 1, 1)).
A controller copies both from the sample it answers, so commands pair with samples exactly
and a restarted driver (a new run starting again at sample 0) is told apart from old or
bogus indices (docs/architecture.md, "Runs and restarts").

This module has no ROS import so that bag analysis and the pure core use it without rclpy.
"""

from __future__ import annotations

import secrets
from enum import StrEnum
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    import numpy as np

SAMPLE_RATE_HZ = 1000.0
"""Rate of the loop (Hz): one sample of every ``/pph/*`` topic per millisecond of sim time;
sample n is at n / SAMPLE_RATE_HZ s of sim time."""

STRUT_COUNT = 6
"""Number of struts, hence of values in every ``/pph/*`` message."""

NEVER_WORSE_DB = 1.0
"""Never worse than off: a band more than this above its level without control is worse
(dB; the twin comparison's ``never_worse`` and the sweep maps' rise scale)."""

STRUT_LABEL = "strut"
"""Label of ``layout.dim[0]``."""

SAMPLE_LABEL_PREFIX = "sample:"
"""Prefix of the label of ``layout.dim[1]``, followed by the decimal sample index."""

RUN_LABEL_PREFIX = "run:"
"""Prefix of the label of ``layout.dim[2]``, followed by the decimal run identity."""

MAX_SAMPLE_INDEX = 2**31 * 1000 - 1
"""Largest valid sample index: its sim time (n ms) still fits ``/clock``'s int32 seconds."""

MAX_RUN_ID = 2**63 - 1
"""Run identities are drawn in [1, MAX_RUN_ID]."""

REFERENCE_FREQUENCY_TOPIC = "/pph/reference_frequency"
"""The rotor's tachometer (driver, when ``rotor_tachometer`` is on): one value, Hz, every
sample, ``layout.dim[0] = ("frequency_hz", 1, 1)`` then the sample and run labels."""

DISTURBANCE_FREQUENCIES_TOPIC = "/pph/disturbance_frequencies"
"""The true frequency (Hz) of every sounding tone (driver, every
``FREQUENCIES_EVERY_SAMPLES``): shaker tones (with their drift), then the rotor's orders."""

NOTCH_FREQUENCIES_TOPIC = "/pph/notch_frequencies"
"""The notch controller's frequency of each configured tone now (Hz, one per tone, every
``FREQUENCIES_EVERY_SAMPLES``): nominal, tracked or following the reference."""

NOTCH_SENSITIVITY_TOPIC = "/pph/notch_sensitivity"
"""The predicted sensitivity |S(f)| (transient local, after each identification): rows
named in ``layout.dim[0].label`` (``SENSITIVITY_ROWS_PREFIX`` + comma-separated names:
``frequency_hz`` then |S| in dB per view), ``layout.dim[1] = ("frequency", F, 1)``."""

NOTCH_HELD_TOPIC = "/pph/notch_held"
"""The notch commands a realtime driver did not apply as they were when due (every
``HELD_REPORT_EVERY_SAMPLES``, reliable): rows ``(first due sample, last due sample, sample
whose command stood in, gain)`` (the force was gain (0..1, the watchdog's ramp) times that
command; -1: no command yet, zero force) flattened,
``layout.dim[0] = (HELD_ROWS_LABEL, 4 R, 4 R)``, then the sample label (the last due sample
the report is complete up to) and the run label."""

HELD_ROWS_LABEL = "held:first_due,last_due,applied,gain"

HELD_REPORT_EVERY_SAMPLES = 100
"""Samples between two reports on ``NOTCH_HELD_TOPIC`` and ``STAND_INS_TOPIC`` (10 Hz, empty
ones included)."""

STAND_INS_TOPIC = "/pph/stand_ins"
"""The due samples at which a realtime driver applied, for some controller's late command, a
stand-in that controller did not compute (:mod:`hexapod_vibration.core.loop.stand_in_log`),
every ``HELD_REPORT_EVERY_SAMPLES``, reliable: rows ``(first due sample, last due sample,
watchdog)`` (watchdog 1: the run holds the watchdog's ramp or zero force) flattened,
``layout.dim[0] = (STAND_IN_ROWS_LABEL, 3 R, 3 R)``, then the sample label (the last due
sample the report is complete up to) and the run label."""

STAND_IN_ROWS_LABEL = "stand_ins:first_due,last_due,watchdog"

NOTCH_FORECAST_TOPIC = "/pph/notch_forecast"
POINTING_FORECAST_TOPIC = "/pph/pointing_forecast"
"""A controller's commands (N) for its next ``FORECAST_SAMPLES`` samples, every
``FORECAST_EVERY_SAMPLES`` while a subscriber listens (a realtime driver, which applies a
row when the command of its sample is late): ``layout.dim[0] = (FORECAST_ROWS_LABEL, 6 K,
6 K)``, rows of six struts, then the sample label (the first row's sample) and the run.
The notch controller forecasts its sinusoids, the pointing controller continues the
oscillation of its last commands."""

FORECAST_TOPICS = {"notch": NOTCH_FORECAST_TOPIC, "pointing": POINTING_FORECAST_TOPIC}
"""The forecast topic of each command stream."""

FORECAST_ROWS_LABEL = "forecast:sample,strut"

FORECAST_SAMPLES = 200
"""Samples a forecast covers (200 ms; beyond, the driver holds, then the watchdog zeroes).

With one core of the two busy, the controllers fell up to 73 samples behind; at 50 the
watchdog zeroed the pointing controller's 45 N seven times in a run. A message of 200 rows
is 9.6 kB, 1 MB/s at 100 Hz."""

FORECAST_EVERY_SAMPLES = 10
"""Samples between two forecasts (100 Hz; each covers the next ``FORECAST_SAMPLES``)."""

FORECAST_PHASE_SAMPLES = {"notch_controller": 0, "pointing_controller": 5}
"""Sample within each ``FORECAST_EVERY_SAMPLES`` after whose answer each controller forecasts.
Both on the same sample, about 0.6 ms of work ran between that sample's answers and a
composed driver's take of them (the two forecasts, 135 and 273 us, their publication and
the driver's two parses, 70 us each): 73-97 % of those samples took over 1 ms, 81-90 % of
all the samples over 1 ms (p99 1.7-2.1 ms; docs/performance.md)."""

FREQUENCY_LABEL = "frequency_hz"
"""``layout.dim[0]`` label of the frequency topics (values in Hz)."""

SENSITIVITY_ROWS_PREFIX = "rows:"

FREQUENCIES_EVERY_SAMPLES = 10
"""Samples between two messages of /pph/disturbance_frequencies and /pph/notch_frequencies
(100 Hz: tones move by at most a few Hz per second)."""

DIAGNOSTICS_EVERY_SAMPLES = 1000
"""Samples between two ``/diagnostics`` statuses of a 1 kHz node (once per simulated second)."""

DIAGNOSTICS_PHASE_SAMPLES = {"pph_driver": 0, "notch_controller": 250, "pointing_controller": 500}
"""Sample within each second at which each node publishes its status: at the same sample
(every whole second) the three nodes, the recorder and the runner all worked at once, and
the realtime loop missed the samples after whole seconds (87 of 477 gaps in a run began in
the first 100 ms of a second, about 45 in each other tenth)."""

DRIVER_STATUS = "pph_driver: loop"
"""``/diagnostics`` status name of the driver's loop."""

NOTCH_STATUS = "notch_controller"
"""``/diagnostics`` status name of the notch controller."""

POINTING_STATUS = "pointing_controller"
"""``/diagnostics`` status name of the pointing controller."""


class NotchState(StrEnum):
    """The notch controller's ``state`` on ``/diagnostics``."""

    IDENTIFYING = "identifying"
    ADAPTING = "adapting"
    ENABLED = "enabled"
    DISABLED = "disabled"
    REFUSED = "refused"
    """Control kept off: the identification gave no usable coefficients or no stable mu."""


class StrutSample(NamedTuple):
    """One received ``/pph/*`` message: six values, and its sample index and run if sent."""

    values: np.ndarray
    """Six values in strut order 1..6 (SI units of the topic), read-only float64."""
    index: int | None
    """Sample index from ``layout.dim[1]``, None if the publisher sent none."""
    run: int | None
    """Run identity from ``layout.dim[2]``, None if the publisher sent none."""


def sample_sim_time(sample: int, sample_rate_hz: float = SAMPLE_RATE_HZ) -> tuple[int, int]:
    """Sim time of loop sample ``sample`` (n / fs s; 0 before sample 0) as (s, ns)."""
    return divmod(int(round(max(sample, 0) * 1e9 / sample_rate_hz)), 1_000_000_000)


class InvalidStrutMessage(ValueError):
    """A ``/pph/*`` message that cannot be used: wrong length, non-finite, bad label or bytes."""


def sample_label(sample_index: int) -> str:
    """Label ``sample:<n>`` of ``layout.dim[1]`` for sample index ``n`` (>= 0).

    Raises:
        ValueError: ``sample_index`` is negative.
    """
    if sample_index < 0:
        raise ValueError(f"sample index must be >= 0, got {sample_index}")
    return f"{SAMPLE_LABEL_PREFIX}{int(sample_index)}"


def run_label(run_id: int) -> str:
    """Label ``run:<id>`` of ``layout.dim[2]`` for run identity ``id`` in [1, MAX_RUN_ID].

    Raises:
        ValueError: ``run_id`` is out of range.
    """
    if not 1 <= run_id <= MAX_RUN_ID:
        raise ValueError(f"run id must be in [1, {MAX_RUN_ID}], got {run_id}")
    return f"{RUN_LABEL_PREFIX}{int(run_id)}"


def new_run_id() -> int:
    """A fresh run identity in [1, MAX_RUN_ID] (random: never the same twice in practice)."""
    return 1 + secrets.randbelow(MAX_RUN_ID)


def _decimal(label: str, prefix: str, maximum: int, what: str) -> int:
    """``n`` of ``<prefix><n>`` (n: ASCII digits, at most ``maximum``)."""
    digits = label[len(prefix):]
    if not (digits.isascii() and digits.isdigit()):
        raise InvalidStrutMessage(
            f"garbled {what} label {label!r}: expected {prefix!r} followed by "
            "a non-negative decimal integer"
        )
    if len(digits) > len(str(maximum)) or int(digits) > maximum:
        raise InvalidStrutMessage(f"{what} label {label!r} is out of range (max {maximum})")
    return int(digits)


def parse_sample_label(label: str) -> int:
    """Parse ``sample:<n>`` (n: ASCII decimal digits, n <= MAX_SAMPLE_INDEX) into ``n``.

    Raises:
        InvalidStrutMessage: Any other label, or an index beyond MAX_SAMPLE_INDEX.
    """
    if not label.startswith(SAMPLE_LABEL_PREFIX):
        raise InvalidStrutMessage(
            f"layout.dim[1] label {label!r} is not {SAMPLE_LABEL_PREFIX!r}<sample index>"
        )
    return _decimal(label, SAMPLE_LABEL_PREFIX, MAX_SAMPLE_INDEX, "sample")


def parse_run_label(label: str) -> int | None:
    """The run identity of a ``layout.dim[2]`` label ``run:<id>``; None for another label.

    Raises:
        InvalidStrutMessage: ``run:`` followed by anything but an id in [1, MAX_RUN_ID].
    """
    if not label.startswith(RUN_LABEL_PREFIX):
        return None
    run = _decimal(label, RUN_LABEL_PREFIX, MAX_RUN_ID, "run")
    if run < 1:
        raise InvalidStrutMessage(f"run label {label!r}: the run id must be >= 1")
    return run


def parse_layout_labels(labels: list[str]) -> tuple[int | None, int | None]:
    """(sample index, run id) from the labels of ``layout.dim``; None for each one absent.

    ``dim[0]``'s label is not checked (a publisher may send six values without a layout);
    ``dim[1]`` must be a sample label if present; ``dim[2]`` is the run if labelled so.

    Raises:
        InvalidStrutMessage: A garbled or out-of-range sample or run label.
    """
    if len(labels) < 2:
        return None, None
    index = parse_sample_label(labels[1])
    run = parse_run_label(labels[2]) if len(labels) > 2 else None
    return index, run
