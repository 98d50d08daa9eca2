"""One declaration of every node parameter: type, default, unit, range, choices, read-only.

Pure data and pure checks (the standard library and the loop's contract only: no rclpy,
no numpy), in the spirit of generate_parameter_library: each node's parameters are declared
once here, and everything else is derived from that declaration:

- the ``ParameterDescriptor`` of each parameter (``ros/parameters.py``), whose range is
  the true one (an open bound is never shown as a closed one);
- the validation, at start-up and at run time alike (:meth:`NodeSpec.check`, plus a
  node's own checks that need its state, e.g. the identified stability bound of ``mu``);
- ``config/pph.yaml`` and the README's parameter table (:func:`params_yaml`,
  :func:`markdown_table`; the tests compare both files with them);
- the parameter list of every node executable's ``--help``;
- the notch controller's settings in the core
  (:class:`~hexapod_vibration.core.control.supervisor.config.NotchConfig`: its fields, their
  defaults and the checks of each value).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from hexapod_vibration.contract import SAMPLE_RATE_HZ

MAX_SHAKER_TONES = 16
MAX_NOTCH_TONES = 16
MAX_ROTOR_ORDERS = 16
MAX_ROTOR_KNOTS = 64
EXECUTORS = ("waitset", "single_threaded", "events")
CLOCK_MODES = ("lockstep", "realtime")
LOCKSTEP_STREAMS = ("notch", "pointing")
ADAPTATION_MODES = ("centralized", "decentralized", "raw")
"""The notch's adaptation coefficients P (``core.control.adaptation.normalized_coefficients``)."""
MU_POLICIES = ("manual", "auto")
"""How the notch sets each tone's rate (``core.control.mu_policy.choose_tone_rates``)."""
IDENTIFICATION_METHODS = ("tones", "broadband")
"""How the notch identifies the plant (test tones at the tones, or a multisine G(f))."""
ANALYSIS_PLACES = ("loop", "process")
"""Where the notch analyses a finished identification (its loop's thread, a worker)."""
STORAGES = ("mcap", "sqlite3")
TYPES = ("bool", "int", "double", "string", "int[]", "double[]", "string[]")


def _number(value: float) -> str:
    """A bound as the README and the descriptors show it (``2^31 - 1`` spelled out)."""
    if value == 2**31 - 1:
        return "2^31 - 1"
    return f"{value:g}"


@dataclass(frozen=True)
class ParameterSpec:
    """The declaration of one parameter.

    ``low``/``high`` bound the value (scalars) or every element (arrays); ``low_open`` /
    ``high_open`` make a bound exclusive. ``constraints`` describes, for the reader, what
    a node checks beyond this declaration (e.g. "below the identified stability bound").
    """

    name: str
    type: str
    default: Any
    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()
    length: int | None = None
    max_length: int | None = None
    distinct: bool = False
    read_only: bool = False
    constraints: str = ""

    def __post_init__(self) -> None:
        """Reject a declaration whose own default does not pass it."""
        if self.type not in TYPES:
            raise ValueError(f"{self.name}: type must be one of {TYPES}, got {self.type!r}")
        reason = self.check(self.default)
        if reason:
            raise ValueError(f"{self.name}: the default does not pass its own spec: {reason}")

    @property
    def is_array(self) -> bool:
        """An array parameter (its bounds and choices apply to every element)."""
        return self.type.endswith("[]")

    @property
    def element_type(self) -> str:
        """``double``, ``string``, ... for an array; the type itself for a scalar."""
        return self.type[:-2] if self.is_array else self.type

    # ---------------------------------------------------------------- validation
    def check(self, value: Any) -> str:
        """Why ``value`` does not satisfy this declaration, or ``""`` when it does."""
        if not self.is_array:
            return self._check_element(self.name, value)
        values = list(value) if isinstance(value, (list, tuple)) or hasattr(value, "tolist") \
            else None
        if values is None:
            return f"{self.name} must be an array of {self.element_type}, got {value!r}"
        if self.length is not None and len(values) != self.length:
            unit = f" ({self.unit})" if self.unit else ""
            return f"{self.name} needs {self.length} values{unit}, got {len(values)}"
        if self.max_length is not None and len(values) > self.max_length:
            return f"{self.name}: at most {self.max_length} values, got {len(values)}"
        for i, element in enumerate(values):
            reason = self._check_element(f"{self.name}[{i}]", element)
            if reason:
                return reason
        if self.distinct and len(set(values)) != len(values):
            return f"{self.name} has duplicate values: {values}"
        return ""

    def _check_element(self, label: str, value: Any) -> str:
        kind = self.element_type
        if kind == "bool":
            return "" if isinstance(value, bool) else f"{label} must be true or false"
        if kind == "string":
            if not isinstance(value, str):
                return f"{label} must be a string, got {value!r}"
            if self.choices and value not in self.choices:
                return f"{label} = {value!r} is not one of: {', '.join(self.choices)}"
            return ""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"{label} must be a number, got {value!r}"
        if kind == "int" and not (isinstance(value, int) or float(value).is_integer()):
            return f"{label} must be an integer, got {value!r}"
        if kind == "double" and not math.isfinite(value):
            return f"{label} must be finite, got {value}"
        return self._check_bounds(label, value)

    def _check_bounds(self, label: str, value: float) -> str:
        shown = f"{label} = {value:g}{self._unit_text()}"
        if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
            relation = "not above" if value == self.low else "below"
            return f"{shown} is {relation} the minimum: {self._must_be()}"
        if self.high is not None and (value > self.high
                                      or (self.high_open and value == self.high)):
            relation = "not below" if value == self.high else "above"
            return f"{shown} is {relation} the maximum: {self._must_be()}"
        return ""

    def _must_be(self) -> str:
        subject = "every element" if self.is_array else self.name
        return f"{subject} must be in {self.interval()}{self._unit_text()}"

    def _unit_text(self) -> str:
        return f" {self.unit}" if self.unit else ""

    # ---------------------------------------------------------------- documentation
    def interval(self) -> str:
        """The range in interval notation, e.g. ``[0.1, 499]``, ``(0, 500)``, ``>= 0``."""
        if self.low is None and self.high is None:
            return ""
        if self.high is None:
            return f"{'>' if self.low_open else '>='} {_number(self.low)}"
        if self.low is None:
            return f"{'<' if self.high_open else '<='} {_number(self.high)}"
        return (f"{'(' if self.low_open else '['}{_number(self.low)}, {_number(self.high)}"
                f"{')' if self.high_open else ']'}")

    def range_text(self) -> str:
        """Every constraint of the declaration in words (descriptor and README table)."""
        parts = []
        if self.choices:
            parts.append(("each one of " if self.is_array else "") + ", ".join(self.choices))
        interval = self.interval()
        if interval:
            parts.append(f"each in {interval}" if self.is_array else interval)
        if self.length is not None:
            parts.append(f"exactly {self.length} values")
        if self.max_length is not None:
            parts.append(f"at most {self.max_length} values")
        if self.distinct:
            parts.append("distinct")
        if self.constraints:
            parts.append(self.constraints)
        return "; ".join(parts)

    def type_text(self) -> str:
        """Type and unit for the README table, e.g. ``double[], Hz``."""
        return f"{self.type}, {self.unit}" if self.unit else self.type


Check = Callable[[Mapping[str, Any]], str]
"""A check of several parameters together: the reason they are refused, or ``""``."""


@dataclass(frozen=True)
class NodeSpec:
    """Every parameter of one node, and the checks of parameters that belong together."""

    node: str
    parameters: tuple[ParameterSpec, ...]
    checks: tuple[Check, ...] = ()
    summary: str = ""
    by_name: dict[str, ParameterSpec] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Index the parameters; reject duplicates and defaults that fail the joint checks."""
        names = [p.name for p in self.parameters]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.node}: duplicate parameter names")
        object.__setattr__(self, "by_name", {p.name: p for p in self.parameters})
        reason = self.check(self.defaults())
        if reason:
            raise ValueError(f"{self.node}: the defaults fail a joint check: {reason}")

    def __getitem__(self, name: str) -> ParameterSpec:
        """The declaration of ``name`` (KeyError if the node has no such parameter)."""
        return self.by_name[name]

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in declaration order."""
        return tuple(p.name for p in self.parameters)

    def defaults(self) -> dict[str, Any]:
        """Every parameter at its default."""
        return {p.name: p.default for p in self.parameters}

    def check(self, values: Mapping[str, Any], changed: Sequence[str] | None = None) -> str:
        """Why ``values`` (every parameter of the node) are refused, or ``""``.

        ``changed``: the parameters whose values are new (all of them at start-up); only
        those are checked one by one, the joint checks always run on the whole set.
        """
        for name in self.names if changed is None else changed:
            spec = self.by_name.get(name)
            if spec is not None:
                reason = spec.check(values[name])
                if reason:
                    return reason
        return self.check_together(values)

    def check_together(self, values: Mapping[str, Any]) -> str:
        """Why ``values`` fail a check of parameters that belong together, or ``""``.

        ``values`` needs the parameters the checks read (e.g. a node's settings without its
        loop scheduling).
        """
        for joint in self.checks:
            reason = joint(values)
            if reason:
                return reason
        return ""


# ------------------------------------------------------------------------ shared
EXECUTOR = ParameterSpec(
    "executor", "string", "waitset",
    "how the node is served: waitset (loop topics from a persistent wait set, the rest by a "
    "SingleThreadedExecutor), single_threaded or events (rclpy's executors for everything)",
    choices=EXECUTORS, read_only=True)
REALTIME_PRIORITY = ParameterSpec(
    "realtime_priority", "int", 0, "real-time priority of the process's threads: 1-98 runs "
    "them under SCHED_FIFO at that priority (needs CAP_SYS_NICE or an rtprio limit), 0 = the "
    "normal scheduler; refused at start-up where the OS does not permit it", low=0, high=98,
    read_only=True)
CPU_AFFINITY = ParameterSpec(
    "cpu_affinity", "int[]", [], "CPUs the process's threads may run on (empty: every CPU it "
    "may use); refused at start-up if one is not available to it", low=0, high=1023,
    max_length=1024, distinct=True, read_only=True)
COMMAND_DELAY = ParameterSpec(
    "command_delay_samples", "int", 0, "the driver applies the command answering sample n "
    "over [n+d, n+d+1): a controller has d+1 periods to answer (a realtime pipeline), and "
    "one behind its loop answers the newest d+1 samples queued (the older ones are past "
    "their deadline); the same d on the driver and the controllers; the notch adds d "
    "to its loop_delay_samples", unit="samples", low=0, high=10, read_only=True)
LOOP_SCHEDULING = (EXECUTOR, REALTIME_PRIORITY, CPU_AFFINITY, COMMAND_DELAY)
"""The parameters of every 1 kHz node on how its loop is served and scheduled."""
MODEL_FILE = ParameterSpec(
    "model_file", "string", "", "physical model YAML (empty: the packaged "
    "config/pph_model.yaml)", read_only=True)


# ------------------------------------------------------------------------ pph_driver
def shaker_tone_arrays(values: Mapping[str, Any]) -> tuple[list[float], list[float],
                                                            list[float]]:
    """The sounding shaker tones: (frequencies Hz, amplitudes N, phases rad), one per tone.

    Tone k sounds when it has a frequency (``shaker_frequencies_hz[k]``) and an amplitude
    (``shaker_amplitudes_n[k]``); its phase is ``shaker_phases_rad[k]``, 0 when missing. A
    value without its partner waits, inert, for it: so each array can be set on its own,
    in any order (``ros2 param set`` one at a time, ``ros2 param load`` one by one), and
    the number of tones changes with one call.
    """
    frequencies = [float(f) for f in values["shaker_frequencies_hz"] or []]
    amplitudes = [float(a) for a in values["shaker_amplitudes_n"] or []]
    phases = [float(p) for p in values["shaker_phases_rad"] or []]
    n = min(len(frequencies), len(amplitudes))
    phases = (phases + [0.0] * n)[:n]
    return frequencies[:n], amplitudes[:n], phases


def shaker_unpaired(values: Mapping[str, Any]) -> str:
    """Which shaker values wait for a partner (``""`` if none): logged, and on /diagnostics."""
    counts = {name: len(values[name] or []) for name in
              ("shaker_frequencies_hz", "shaker_amplitudes_n", "shaker_phases_rad")}
    tones = min(counts["shaker_frequencies_hz"], counts["shaker_amplitudes_n"])
    waiting = [f"{n - tones} of {name}" for name, n in counts.items() if n > tones]
    if not waiting:
        return ""
    return (f"{tones} shaker tone(s) sound; waiting for a partner: {', '.join(waiting)} "
            "(a tone needs a frequency and an amplitude)")


def check_shaker_drift(values: Mapping[str, Any]) -> str:
    """Every sounding tone, drifted by +-``shaker_drift_hz``, stays in (0, fs/2) Hz."""
    drift = float(values["shaker_drift_hz"])
    nyquist = SAMPLE_RATE_HZ / 2.0
    for k, f in enumerate(shaker_tone_arrays(values)[0]):
        if f - drift <= 0.0 or f + drift >= nyquist:
            return (f"shaker tone {k + 1} at {f:g} Hz drifting by +-{drift:g} Hz "
                    f"(shaker_drift_hz) would leave (0, {nyquist:g}) Hz")
    return ""


def rotor_arrays(values: Mapping[str, Any]) -> tuple[list[float], list[float], list[float],
                                                      list[float]]:
    """The rotor's sounding orders and amplitudes (N), and its profile's knots (s, Hz).

    As for the shaker, order k sounds once it has an amplitude (``rotor_amplitudes_n[k]``)
    and knot k counts once it has a time and a speed: each array can be set on its own. No
    sounding order: no rotor.
    """
    orders = [float(x) for x in values["rotor_orders"] or []]
    amplitudes = [float(x) for x in values["rotor_amplitudes_n"] or []]
    times = [float(x) for x in values["rotor_profile_time_s"] or []]
    speeds = [float(x) for x in values["rotor_profile_speed_hz"] or []]
    n, k = min(len(orders), len(amplitudes)), min(len(times), len(speeds))
    return orders[:n], amplitudes[:n], times[:k], speeds[:k]


def rotor_unpaired(values: Mapping[str, Any]) -> str:
    """Which rotor values wait for a partner (``""`` if none): logged by the driver."""
    pairs = (("rotor_orders", "rotor_amplitudes_n"),
             ("rotor_profile_time_s", "rotor_profile_speed_hz"))
    waiting, paired = [], []
    for pair in pairs:
        counts = [len(values[name] or []) for name in pair]
        paired.append(min(counts))
        waiting += [f"{n - min(counts)} of {name}" for name, n in zip(pair, counts, strict=True)
                    if n > min(counts)]
    if not waiting:
        return ""
    return (f"{paired[0]} rotor order(s) sound, profile of {paired[1]} knot(s); waiting for "
            f"a partner: {', '.join(waiting)}")


def check_rotor(values: Mapping[str, Any]) -> str:
    """The sounding rotor: a profile (times increasing), every order below fs/2 at top speed."""
    orders, _, times, speeds = rotor_arrays(values)
    if not orders:
        return ""
    if not times:
        return "the rotor needs a speed profile (rotor_profile_time_s, rotor_profile_speed_hz)"
    if any(b <= a for a, b in zip(times, times[1:], strict=False)):
        return f"rotor_profile_time_s must be strictly increasing, got {times}"
    nyquist = SAMPLE_RATE_HZ / 2.0
    top = max(orders) * max(speeds)
    if top >= nyquist:
        return (f"rotor order {max(orders):g} at {max(speeds):g} Hz sounds at {top:g} Hz, "
                f"not below {nyquist:g} Hz (fs/2)")
    return ""


PPH_DRIVER = NodeSpec("pph_driver", summary="the simulated hexapod (plant, sensors, shaker)",
                      checks=(check_shaker_drift, check_rotor), parameters=(
    ParameterSpec("clock_mode", "string", "lockstep", "lockstep: advance when the commands "
                  "of the sample arrived (or lockstep_timeout_s passed); realtime: paced at "
                  "1 kHz wall clock", choices=CLOCK_MODES, read_only=True),
    MODEL_FILE,
    ParameterSpec("nonlinear", "bool", True, "free-play and stroke-dependent force constant "
                  "on (false: the linear reference plant)", read_only=True),
    ParameterSpec("seed", "int", 1, "random seed of the sensor and shaker noise",
                  low=0, high=2**31 - 1, read_only=True),
    ParameterSpec("shaker_frequencies_hz", "double[]", [40.0], "shaker tone frequencies; "
                  "tone k sounds once it also has an amplitude", unit="Hz", low=0.1,
                  high=499.0, max_length=MAX_SHAKER_TONES,
                  constraints="each +-shaker_drift_hz within (0, 500) Hz"),
    ParameterSpec("shaker_amplitudes_n", "double[]", [80.0], "shaker tone amplitudes, one "
                  "per frequency (tone k is silent until it has one)", unit="N peak",
                  low=0.0, high=100.0, max_length=MAX_SHAKER_TONES),
    ParameterSpec("shaker_phases_rad", "double[]", [], "shaker tone phases, one per tone; "
                  "a missing one is 0", unit="rad", low=-10.0, high=10.0,
                  max_length=MAX_SHAKER_TONES),
    ParameterSpec("shaker_drift_hz", "double", 0.0, "slow sinusoidal frequency drift of "
                  "every tone (peak)", unit="Hz", low=0.0, high=5.0),
    ParameterSpec("shaker_drift_period_s", "double", 60.0, "period of that drift",
                  unit="s", low=1.0, high=3600.0),
    ParameterSpec("shaker_noise_rms_n", "double", 0.0, "broadband shaker noise",
                  unit="N RMS", low=0.0, high=20.0),
    ParameterSpec("rotor_orders", "double[]", [], "rotating machine at the shaker's point: "
                  "harmonic orders of its speed (may be non-integer); order k sounds once it "
                  "also has an amplitude; empty = no rotor", low=0.0, high=100.0,
                  low_open=True, max_length=MAX_ROTOR_ORDERS,
                  constraints="order x top speed < 500 Hz"),
    ParameterSpec("rotor_amplitudes_n", "double[]", [], "rotor order amplitudes at "
                  "rotor_reference_speed_hz, scaling with the speed squared", unit="N peak",
                  low=0.0, high=100.0, max_length=MAX_ROTOR_ORDERS),
    ParameterSpec("rotor_reference_speed_hz", "double", 50.0, "speed at which the rotor "
                  "amplitudes are given", unit="Hz", low=0.0, high=499.0, low_open=True),
    ParameterSpec("rotor_profile_time_s", "double[]", [0.0], "rotor speed profile: knot "
                  "times (sim time; speed held before the first and after the last)",
                  unit="s", low=0.0, high=1e6, max_length=MAX_ROTOR_KNOTS,
                  constraints="strictly increasing"),
    ParameterSpec("rotor_profile_speed_hz", "double[]", [50.0], "rotor speed at each knot, "
                  "linear in between", unit="Hz", low=0.0, high=499.0,
                  max_length=MAX_ROTOR_KNOTS),
    ParameterSpec("rotor_tachometer", "bool", False, "publish the rotor speed on "
                  "/pph/reference_frequency every sample (Hz, with the sample index)"),
    ParameterSpec("test_sine_frequency_hz", "double", 40.0, "sinusoid added to every "
                  "actuator in phase (paper Fig. 4)", unit="Hz", low=0.1, high=499.0),
    ParameterSpec("test_sine_amplitude_n", "double", 0.0, "its amplitude; 0 = off",
                  unit="N peak", low=0.0, high=40.0),
    ParameterSpec("command_timeout_samples", "int", 5, "watchdog: a command stream older "
                  "than this many samples (1 ms each) is dropped to zero force",
                  unit="samples", low=1, high=1000),
    ParameterSpec("command_fade_samples", "int", 100, "watchdog: a dropped stream's force "
                  "falls to zero over this many samples (a smooth ramp from its last "
                  "command) and rises back as smoothly when it commands again; 0 = a step",
                  unit="samples", low=0, high=1000),
    ParameterSpec("lockstep_timeout_s", "double", 2.0, "lockstep: longest wait for the "
                  "commands of one sample before advancing without them", unit="s",
                  low=0.001, high=10.0),
    ParameterSpec("hold_at_time_s", "double", -1.0, "breakpoint: stop before publishing "
                  "the sample at this sim time until it is changed (realtime: the clock "
                  "stops there and resumes when it is released); -1 = never",
                  unit="s", low=-1.0, high=1e6),
    *LOOP_SCHEDULING,
    ParameterSpec("lockstep_controllers", "string[]", list(LOCKSTEP_STREAMS), "controllers "
                  "the lockstep driver waits for before sample 0 and then every sample while "
                  "they are connected (may be empty)", choices=LOCKSTEP_STREAMS,
                  distinct=True, read_only=True),
))


# ------------------------------------------------------------------------ notch_controller
UPDATE_LOWPASS_AUTO = -1.0
"""``update_lowpass_hz`` for "automatic": :data:`AUTO_UPDATE_LOWPASS_HZ` for fixed tones, the
paper's update (0) for tones that move (``frequency_tracking``, ``reference_harmonics``)."""
AUTO_UPDATE_LOWPASS_HZ = 10.0
"""The automatic update low-pass of fixed tones (Hz). Table 1 at mu 0.002: the 18.7 Hz
loop mode's predicted rise 1.9 dB -> 0.3 dB, largest third-octave rise over the twin
+1.74 -> +0.46 dB. Tones that move keep the paper's update: with it the mu policy's rate
for ``drift_tracking`` fell from 0.00089 to 0.00036 and the tone was lost at the drift's
turning point (guard fade, +9 dB at 50 Hz over the twin)."""


def moving_tones(values: Mapping[str, Any]) -> bool:
    """Whether the notch's tones may move: ``frequency_tracking`` or ``reference_harmonics``."""
    return bool(values["frequency_tracking"]) or bool(values["reference_harmonics"])


def update_lowpass_corner_hz(values: Mapping[str, Any]) -> float:
    """The update low-pass corner (Hz) the settings ask for: ``update_lowpass_hz`` resolved.

    :data:`UPDATE_LOWPASS_AUTO` is :data:`AUTO_UPDATE_LOWPASS_HZ` for fixed tones and 0 (the
    paper's update) for tones that move (:func:`moving_tones`).
    """
    corner = float(values["update_lowpass_hz"])
    if corner != UPDATE_LOWPASS_AUTO:
        return corner
    return 0.0 if moving_tones(values) else AUTO_UPDATE_LOWPASS_HZ


def check_update_lowpass(values: Mapping[str, Any]) -> str:
    """``update_lowpass_hz`` is -1 (automatic) or a corner >= 0 Hz."""
    corner = float(values["update_lowpass_hz"])
    if corner == UPDATE_LOWPASS_AUTO or corner >= 0.0:
        return ""
    return (f"update_lowpass_hz = {corner:g} Hz: must be {UPDATE_LOWPASS_AUTO:g} (automatic: "
            f"{AUTO_UPDATE_LOWPASS_HZ:g} Hz for fixed tones, 0 for tones that move), 0 (the "
            "paper's update) or a corner in (0, 100] Hz")


def check_identification(values: Mapping[str, Any]) -> str:
    """What needs the broadband identification's G(f) is not asked of the test tones.

    ``mu_policy: auto`` bounds a rise predicted on G(f); tones that move are acquired on its
    disturbance lines and take their P from G(f) where they move (a test-tone
    identification measures G at the nominal tones only, and is refused when a line sits
    off its tone: the disturbance moves between its two baselines).
    """
    if values["identification"] != "tones":
        return ""
    if values["mu_policy"] == "auto":
        return ("mu_policy auto needs identification: broadband (the rise it bounds is "
                "predicted on the identified G(f)); with identification: tones set mu_policy "
                "manual first (every tone at mu, no bound on the rise off the tones)")
    if values["frequency_tracking"]:
        return ("frequency_tracking needs identification: broadband (a tracked tone starts on "
                "its disturbance lines and takes P from G(f) where it moves; test tones "
                "measure G at the nominal tones only, and are refused when the line sits off "
                "the tone)")
    if values["reference_harmonics"]:
        return ("reference_harmonics needs identification: broadband (tones that follow the "
                "reference take P from G(f) where they move; test tones measure G at the "
                "nominal tones only)")
    return ""


NOTCH_CONTROLLER = NodeSpec("notch_controller", summary="six decentralized Adaptive Notch "
                            "Cancellers (the paper's algorithm)",
                            checks=(check_update_lowpass, check_identification), parameters=(
    ParameterSpec("mu", "double", 0.002, "normalised adaptation rate: the weights converge "
                  "as (1 - mu)^n", unit="1/sample", low=0.0, high=1.0,
                  constraints="below the identified stability bound (eq. 18 with the loop "
                  "delay; mu_bound on /diagnostics)"),
    ParameterSpec("tone_frequencies_hz", "double[]", [40.0, 80.0], "tones to cancel; an "
                  "unknown tone is identified first", unit="Hz", low=0.0,
                  high=SAMPLE_RATE_HZ / 2.0, low_open=True, high_open=True,
                  max_length=MAX_NOTCH_TONES, distinct=True),
    ParameterSpec("enabled", "bool", True, "control output on (ramped, bumpless); while off "
                  "the weights are frozen and kept"),
    ParameterSpec("adaptation", "string", "decentralized", "adaptation coefficient: "
                  "decentralized = six SISO loops, each normalised by its own strut's "
                  "identified gain and phase (the paper); centralized = -2 G^-1 (6x6); "
                  "raw = the paper as printed (P = I, mu unnormalised)",
                  choices=ADAPTATION_MODES),
    ParameterSpec("auto_identify", "bool", True, "identify the plant at start-up and "
                  "whenever unknown tones appear; false: decentralized and centralized "
                  "adapt only after a ~/identify call (raw adapts without one, guarded)"),
    ParameterSpec("identify_delay_s", "double", 1.0, "wait after the first sample before "
                  "the start-up identification (samples' time)", unit="s", low=0.0,
                  high=60.0),
    ParameterSpec("identification_amplitude_n", "double", 2.0, "test-tone amplitude per "
                  "tone during identification", unit="N peak", low=0.01, high=20.0),
    ParameterSpec("identification_settle_s", "double", 0.1, "discarded settling time per "
                  "identification segment", unit="s", low=0.0, high=5.0, read_only=True),
    ParameterSpec("identification_measure_s", "double", 0.3, "fitted time per "
                  "identification segment", unit="s", low=0.05, high=10.0, read_only=True),
    ParameterSpec("dc_cutoff_hz", "double", 0.5, "DC-blocker corner", unit="Hz", low=0.01,
                  high=10.0, read_only=True),
    ParameterSpec("loop_delay_samples", "double", 2.0, "loop delay used in the stability "
                  "bound: 1 for the ZOH + anti-aliasing group delay; the node adds its "
                  "command_delay_samples", unit="samples",
                  low=0.0, high=20.0, read_only=True),
    ParameterSpec("ramp_s", "double", 0.05, "enable/disable and removed-tone fade time",
                  unit="s", low=0.0, high=5.0),
    ParameterSpec("frequency_tracking", "bool", False, "estimate each tone's frequency "
                  "online; the oscillators follow it (estimates on /pph/notch_frequencies)"),
    ParameterSpec("tracking_range_hz", "double", 2.0, "largest deviation of a tracked tone "
                  "from its nominal frequency", unit="Hz", low=0.0, high=50.0,
                  low_open=True),
    ParameterSpec("reference_harmonics", "double[]", [], "one order per tone: tone k "
                  "follows order_k x /pph/reference_frequency while it arrives; empty = "
                  "no reference", low=0.0, low_open=True, max_length=MAX_NOTCH_TONES,
                  constraints="empty or one order per tone"),
    ParameterSpec("reference_timeout_s", "double", 0.1, "a reference older than this is "
                  "stale: the tones fall back to tracking or their nominal frequencies",
                  unit="s", low=0.002, high=10.0),
    ParameterSpec("harmonics", "int", 0, "also cancel orders 2..harmonics+1 of every "
                  "tone, following it", low=0, high=MAX_NOTCH_TONES - 1,
                  constraints=f"tones x (harmonics + 1) <= {MAX_NOTCH_TONES}"),
    ParameterSpec("mu_policy", "string", "auto", "auto = per tone the largest rate up to "
                  "mu whose predicted rise off the tones stays within max_rise_db (needs "
                  "identification broadband); manual = every tone at mu, a warning when the "
                  "predicted rise exceeds max_rise_db (the paper)", choices=MU_POLICIES),
    ParameterSpec("max_rise_db", "double", 0.7, "largest predicted rise of the vibration "
                  "off the tones (the guard's 1 dB margin less the prediction's error)",
                  unit="dB", low=0.1, high=20.0),
    ParameterSpec("divergence_guard", "bool", True, "back off (lower mu, then fade out) "
                  "when control makes a band worse than its level before control"),
    ParameterSpec("guard_margin_db", "double", 1.0, "rise over the level before control "
                  "that counts as worse; also the least predicted reduction of a fixed "
                  "tone's line (located from the weights' turning) that keeps control on",
                  unit="dB", low=0.1, high=10.0),
    ParameterSpec("weight_limit_n", "double", 40.0, "anti-windup: each strut's weights "
                  "never add up to more than this (the actuator's dynamic rating)",
                  unit="N", low=0.0, high=1000.0, low_open=True),
    ParameterSpec("identification", "string", "broadband", "broadband = a 10 s multisine "
                  "over 0..fs/2 that survives a disturbance next to a tone (Nyquist bound on "
                  "G(f), mu_policy auto, predicted sensitivity, moving tones); tones = test "
                  "tones at the tones (3.2 s, eq. 18 bound: the paper)",
                  choices=IDENTIFICATION_METHODS,
                  constraints="broadband for mu_policy auto, frequency_tracking and "
                  "reference_harmonics"),
    ParameterSpec("update_lowpass_hz", "double", UPDATE_LOWPASS_AUTO, "corner of a "
                  "first-order low-pass on each tone's weight correction: the canceller's "
                  "gain far from its tones falls by update_lowpass_hz / |f - f_tone| more (no "
                  "rise of a loop mode tens of Hz away); 0 = the paper's update; -1 = "
                  f"automatic: {AUTO_UPDATE_LOWPASS_HZ:g} Hz for fixed tones, 0 for tones "
                  "that move (frequency_tracking, reference_harmonics; fixed at start-up)",
                  unit="Hz", low=UPDATE_LOWPASS_AUTO, high=100.0, read_only=True,
                  constraints="-1 or in [0, 100]"),
    ParameterSpec("identification_analysis", "string", "loop", "where the analysis of a "
                  "finished identification runs (~0.8 s of CPU after a broadband one): "
                  "loop = on the loop's thread, one piece per sample (deterministic, for "
                  "lockstep); process = a worker process on the normal scheduler, while the "
                  "loop keeps its deadline, and so does a change of tones or adaptation "
                  "with G(f) known (its Nyquist limit, ~0.6 s; executor waitset) "
                  "(realtime; the launch file's clock_mode:=realtime and experiment "
                  "--realtime choose it)", choices=ANALYSIS_PLACES,
                  read_only=True),
    *LOOP_SCHEDULING,
))


# ------------------------------------------------------------------------ pointing_controller
POINTING_CONTROLLER = NodeSpec("pointing_controller", summary="the low-pass pointing law "
                               "(pose from the eddy sensors, strut forces out)", parameters=(
    ParameterSpec("target_tilt_x_deg", "double", 0.0, "commanded tilt about x", unit="deg",
                  low=-2.5, high=2.5, constraints="tilt norm of x and y <= 2.5 deg"),
    ParameterSpec("target_tilt_y_deg", "double", 0.0, "commanded tilt about y", unit="deg",
                  low=-2.5, high=2.5, constraints="tilt norm of x and y <= 2.5 deg"),
    ParameterSpec("target_twist_deg", "double", 0.0, "commanded twist about z", unit="deg",
                  low=-10.0, high=10.0),
    ParameterSpec("target_translation_m", "double[]", [0.0, 0.0, 0.0], "commanded "
                  "translation x, y, z of the payload", unit="m", low=-1e-3, high=1e-3,
                  length=3, constraints="the pose's strokes within 95 % of the actuators'"),
    ParameterSpec("bandwidth_hz", "double", 1.5, "pointing bandwidth: the integral pole, far "
                  "below the vibration tones", unit="Hz", low=0.05, high=5.0),
    ParameterSpec("damping_ratio", "double", 0.7, "damping given to the suspension modes",
                  low=0.05, high=2.0),
    ParameterSpec("output_lowpass_hz", "double", 15.0, "2nd-order low-pass on the forces",
                  unit="Hz", low=2.0, high=100.0),
    ParameterSpec("enabled", "bool", True, "pointing forces on (off: zero force, integral "
                  "reset)"),
    MODEL_FILE,
    *LOOP_SCHEDULING,
))


# ------------------------------------------------------------------------ pph_recorder
PPH_RECORDER = NodeSpec("pph_recorder", summary="records the contract topics into a rosbag2 "
                        "bag", parameters=(
    ParameterSpec("bag_path", "string", "", "rosbag2 bag directory to create (must not "
                  "exist); empty: rosbag2_<date>-<time> in the current directory",
                  read_only=True),
    ParameterSpec("storage", "string", "mcap", "rosbag2 storage plugin", choices=STORAGES,
                  read_only=True),
    ParameterSpec("run_record", "string", "", "JSON run record stored in metadata.yaml "
                  "custom_data (hexapod_vibration.run); given by the experiment runner in its "
                  "params file", read_only=True),
))

NODE_SPECS: dict[str, NodeSpec] = {spec.node: spec for spec in (
    PPH_DRIVER, NOTCH_CONTROLLER, POINTING_CONTROLLER, PPH_RECORDER)}
"""Every node's parameters, by node name."""
LOOP_NODES = ("pph_driver", "notch_controller", "pointing_controller")
"""The nodes ``config/pph.yaml`` configures (the recorder takes its two on the command line)."""
RCLPY_PARAMETERS = frozenset({"use_sim_time", "start_type_description_service"})
"""Parameters rclpy declares on every node itself."""


# ------------------------------------------------------------------------ generated files
def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"' if value == "" else value
    if isinstance(value, list):
        return "[" + ", ".join(_yaml_value(v) for v in value) + "]"
    return repr(float(value)) if isinstance(value, float) else str(value)


def _yaml_comment(spec: ParameterSpec) -> str:
    text = spec.description
    if spec.unit:
        text += f" ({spec.unit})"
    constraint = spec.range_text()
    if constraint:
        text += f"; {constraint}"
    return ("(ro) " if spec.read_only else "") + text


def params_yaml(nodes: Sequence[str] = LOOP_NODES) -> str:
    """``config/pph.yaml``: every parameter of ``nodes`` at its default, documented."""
    lines = [
        "# Parameters of the nodes of hexapod_vibration, every one at its default.",
        "# GENERATED from hexapod_vibration/parameter_specs.py (test/test_parameter_specs.py",
        "# checks it): change a parameter there, then run",
        "#   python -m hexapod_vibration.parameter_specs --write-config",
        "# Use: ros2 run hexapod_vibration pph_driver --ros-args --params-file \\",
        "#        $(ros2 pkg prefix --share hexapod_vibration)/config/pph.yaml",
        "#      (launch/pph.launch.py loads this file from the package's share directory).",
        "# (ro) = read-only: set at start-up only. use_sim_time (rclpy's own parameter of",
        "# every node) stays false: the driver is the time source (/clock).",
    ]
    for node in nodes:
        lines += ["", f"{node}:", "  ros__parameters:"]
        for spec in NODE_SPECS[node].parameters:
            lines.append(f"    {spec.name}: {_yaml_value(spec.default)}")
            lines += textwrap.wrap(_yaml_comment(spec), 96, initial_indent="      # ",
                                   subsequent_indent="      #   ")
    return "\n".join(lines) + "\n"


def markdown_table(nodes: Sequence[str] = (*LOOP_NODES, "pph_recorder")) -> str:
    """The README's parameter table (one row per parameter)."""
    rows = ["| node | parameter | type, unit | range | default |", "|---|---|---|---|---|"]
    for node in nodes:
        for i, spec in enumerate(NODE_SPECS[node].parameters):
            name = f"`{spec.name}`" + (" (ro)" if spec.read_only else "")
            default = _yaml_value(spec.default)
            rows.append(f"| {node if i == 0 else ''} | {name} | {spec.type_text()} | "
                        f"{spec.range_text().replace('|', '/')} | {default} |")
    return "\n".join(rows)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m hexapod_vibration.parameter_specs [--write-config]``: print or write."""
    import sys
    from pathlib import Path

    args = list(sys.argv[1:] if argv is None else argv)
    if args == ["--write-config"]:
        path = Path(__file__).resolve().parent.parent / "config" / "pph.yaml"
        path.write_text(params_yaml(), encoding="utf-8")
        print(f"wrote {path}")
        return 0
    if args:
        print("usage: python -m hexapod_vibration.parameter_specs [--write-config]",
              file=sys.stderr)
        return 2
    print(markdown_table())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
