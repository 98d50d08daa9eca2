"""Hostile loop messages against the driver and the pointing controller, as real processes.

Each kind once broke a node: one malformed serialized message killed it (rclpy's
deserializer raised RMWError), a huge ``dims`` count decoded to garbage that was applied,
one absurd sample index stopped a controller for good, and nothing checked values against
the physical range. Here every kind is sent (bytes published as they are) while the loop is
held at a breakpoint and then while it runs in lockstep; the nodes must live, count each
kind on /diagnostics, and act exactly as if nothing had been sent: from the breakpoint on
(where the pointing law is reset by switching it off and on) the pointing controller's
commands are replayed bit for bit by the same law stepped on the driver's eddy samples
alone, and the driver applied the pointing command alone at every sample.
"""

from __future__ import annotations

import itertools
import struct

import numpy as np
from node_graph import Diagnostics, ParameterClient, StrutTopic, start_pointing_loop, wait_until
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.cdr import encode_strut_cdr
from hexapod_vibration.contract import DRIVER_STATUS, NOTCH_STATUS, POINTING_STATUS
from hexapod_vibration.core.control.pointing import PointingGains
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import saturate_commands
from hexapod_vibration.core.model.sensors import EddySensorArray
from hexapod_vibration.core.sim.closed_loop import make_pointing_controller
from hexapod_vibration.paths import config_path

MODEL = load_model_config(config_path("pph_model.yaml"))
FIRST_HOLD = 1000
SECOND_HOLD = 3000
STRAY_RUN = 987654321


def _malformed(raw: bytes) -> dict[str, bytes]:
    """The issue's malformed bytes, made from a well-formed message ``raw``."""
    huge_dims = bytearray(raw)
    huge_dims[4:8] = struct.pack("<I", 0xFFFFFFFF)
    return {"truncated_by_8": raw[:-8], "truncated_at_half": raw[:len(raw) // 2],
            "header_only": raw[:4], "ff_garbage": b"\xff" * len(raw),
            "big_endian_header": b"\x00\x00" + raw[2:], "huge_dims": bytes(huge_dims)}


def _hostile_eddy(index: int, round_: int) -> list[bytes]:
    """Malformed, beyond the gaps' range, absurd or foreign indices (none is applicable).

    The absurd index and the stray run differ from one round to the next: three consistent
    ones in a row would look like a restarted driver and be followed (by design). Each round
    is rotated by one: the controller takes the newest of what is queued at a wake-up
    (``latest_only``), so only the last of a burst is sure to be judged.
    """
    good = encode_strut_cdr(np.full(6, 1e-5), index)
    absurd = 999_999_999 + (round_ % 2) * 10**7
    burst = [*_malformed(good).values(),
            encode_strut_cdr(np.full(6, 1e300), index),            # finite, impossible
            encode_strut_cdr(np.full(6, 1.0), index),              # 1 m gaps
            _unindexed(np.full(6, 1e300)),                         # old: taken as next
            encode_strut_cdr(np.full(6, 1e-5), absurd),            # absurd but valid index
            encode_strut_cdr(np.full(6, 1e-5), index + 1, STRAY_RUN + round_),  # stray run
            _label(np.full(6, 1e-5), "sample:99999999999999999999")]
    shift = round_ % len(burst)
    return burst[shift:] + burst[:shift]


def _hostile_commands(index: int, run: int) -> list[bytes]:
    good = encode_strut_cdr(np.full(6, 5.0), index, run)
    return [*_malformed(good).values(),
            encode_strut_cdr(np.full(6, 1e300), index, run),       # beyond the actuator
            encode_strut_cdr(np.full(6, 71.0), index, run),
            encode_strut_cdr(np.full(6, 5.0), index, STRAY_RUN),   # another run
            encode_strut_cdr(np.full(6, 5.0), index + 10**6, run)]  # the future


def _unindexed(values: np.ndarray) -> bytes:
    from rclpy.serialization import serialize_message

    from hexapod_vibration.ros.messages import make_strut_array
    return serialize_message(make_strut_array(values, None))


def _label(values: np.ndarray, label: str) -> bytes:
    from rclpy.serialization import serialize_message

    from hexapod_vibration.ros.messages import make_strut_array
    msg = make_strut_array(values, 0)
    msg.layout.dim[1].label = label
    return serialize_message(msg)


def _replayed_pointing(eddy: list[np.ndarray]) -> np.ndarray:
    """The pointing controller's commands, from its law stepped on the driver's samples."""
    height = float(MODEL.geometry.top_joints_m[0, 2])
    law = make_pointing_controller(MODEL, EddySensorArray(MODEL.eddy, height).sensing_matrix,
                                   MODEL.simulation.sample_rate_hz)
    law.set_gains(PointingGains(force_limit_n=MODEL.strut.force_limit_static_n))
    law.set_target(np.zeros(6), MODEL.strut.stroke_limit_m)
    return np.array([law.step(gaps).copy() for gaps in eddy])


def test_hostile_messages_are_counted_and_change_nothing(ros_context, node_processes):
    driver, pointing = start_pointing_loop(node_processes,
                                           "-p", f"hold_at_time_s:={FIRST_HOLD / 1000}")
    processes = (driver, pointing)
    node = ros_context.create_node("hostile_publisher")
    eddy, pointing_cmd = StrutTopic(node, "/pph/eddy"), StrutTopic(node, "/pph/pointing_command")
    force = StrutTopic(node, "/pph/actuator_force")
    diagnostics = Diagnostics(node)
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    to_pointing = node.create_publisher(Float64MultiArray, "/pph/eddy", qos)
    to_driver = node.create_publisher(Float64MultiArray, "/pph/notch_command", qos)
    driver_params = ParameterClient(ros_context, node, "pph_driver")
    pointing_params = ParameterClient(ros_context, node, "pointing_controller")

    def logs() -> str:
        return "\n".join(p.output() for p in processes)

    def run() -> int | None:
        """The driver's run (None from a driver without one)."""
        value = diagnostics.value(DRIVER_STATUS, "run")
        return int(value) if value else None

    def last(topic: StrutTopic) -> int:
        """Last index of the driver's run (this test sends other indices itself)."""
        return max(topic.by_run.get(run(), {0: None}))

    def held_at(sample: int) -> bool:
        """The driver says it holds at ``sample``.

        The hold is re-announced every 0.5 s; the topics' last samples may have gone out
        before this listener was matched.
        """
        return (diagnostics.value(DRIVER_STATUS, "held") == "true"
                and diagnostics.int_value(DRIVER_STATUS, "sample") == sample)

    def newest_sample() -> int:
        """The loop's last sample as far as this listener knows (topics or diagnostics)."""
        return max(last(force), diagnostics.int_value(DRIVER_STATUS, "sample") - 1)

    rounds = itertools.count()

    def send_hostile() -> None:
        index = newest_sample()
        for raw in _hostile_eddy(index, next(rounds)):
            to_pointing.publish(raw)
        for raw in _hostile_commands(index, run() or 1):
            to_driver.publish(raw)

    assert wait_until(ros_context, lambda: held_at(FIRST_HOLD)), logs()
    # While the loop is held (until the driver counted one round), then while it runs to
    # the second breakpoint. The controller reports its counts every 1000 samples.
    def pointing_counted() -> bool:
        """The pointing controller judged each kind at least once (its periodic status)."""
        return all(diagnostics.int_value(POINTING_STATUS, key) > 0
                   for key in ("malformed", "out_of_range", "unconfirmed"))

    counted = wait_until(ros_context, lambda: all(p.running() for p in processes) and (
        diagnostics.int_value(DRIVER_STATUS, "notch_malformed") >= 6) and pointing_counted(),
        step=send_hostile)
    assert counted, (diagnostics.values(DRIVER_STATUS), logs())
    for flag in (False, True):      # the law starts afresh at FIRST_HOLD: replayable
        assert pointing_params.set("enabled", flag).successful
    # Every sample of the judged window must reach this listener: the loop goes on only
    # once its subscriptions matched the nodes' publishers (discovery on a loaded machine
    # can take longer than the first hold; /pph/eddy has this test's own publisher too).
    assert wait_until(ros_context, lambda: (
        eddy.subscription.get_publisher_count() >= 2
        and pointing_cmd.subscription.get_publisher_count() >= 1
        and force.subscription.get_publisher_count() >= 1)), logs()
    assert driver_params.set("hold_at_time_s", SECOND_HOLD / 1000).successful
    # held, and this listener has the window's last sample on every judged topic (the hold
    # is announced on /diagnostics, which may overtake the loop topics' last messages: a
    # loaded run judged before the last 294 pointing commands had come in)
    assert wait_until(ros_context, lambda: held_at(SECOND_HOLD) and all(
        last(topic) >= SECOND_HOLD - 1 for topic in (eddy, pointing_cmd, force)),
        step=send_hostile), logs()
    assert all(p.running() for p in processes), logs()

    # Counted on /diagnostics, by reason, as WARN.
    point, drive = diagnostics.values(POINTING_STATUS), diagnostics.values(DRIVER_STATUS)
    print(f"pointing: {point}\ndriver: {drive}")
    for key in ("malformed", "out_of_range", "unconfirmed"):
        assert int(point[key]) > 0, (key, point)
    for key in ("malformed", "out_of_range", "other_run", "future"):
        assert int(drive[f"notch_{key}"]) > 0, (key, drive)
    assert diagnostics.latest[POINTING_STATUS].level == diagnostics.latest[POINTING_STATUS].WARN
    assert diagnostics.latest[DRIVER_STATUS].level == diagnostics.latest[DRIVER_STATUS].WARN

    # Nothing applied or adapted on: the pointing controller answered every sample with
    # what its law gives on the driver's samples alone, and the driver applied that alone.
    window = range(FIRST_HOLD, SECOND_HOLD)
    ours = eddy.by_run[run()]
    absent = [n for n in window if n not in ours]
    assert not absent, (absent[:20], len(absent), eddy.messages, eddy.invalid)
    commands = pointing_cmd.by_run[run()]
    missing = [n for n in window if n not in commands]
    assert not missing, (missing[:20], len(missing), point, drive)
    np.testing.assert_allclose(np.array([commands[n] for n in window]),
                               _replayed_pointing([ours[n] for n in window]), rtol=0, atol=1e-12)
    applied = force.by_run[run()]
    for n in window:
        np.testing.assert_array_equal(
            applied[n], saturate_commands(np.zeros(6), commands[n], MODEL.strut), str(n))
    for process in processes:
        assert process.stop() == 130, process.output()     # SIGINT: 128 + 2


def test_hostile_accelerations_never_reach_the_notch_weights(ros_context, node_processes):
    """Regression: one accel message of 6 x 1e300 took the weights from 9.9 N to 7.1e298 N."""
    driver = node_processes.start("pph_driver", "--ros-args", "-p",
                                  "lockstep_controllers:=[notch]")
    notch = node_processes.start("notch_controller", "--ros-args", "-p", "adaptation:=raw",
                                 "-p", "mu:=1e-5", "-p", "tone_frequencies_hz:=[40.0]",
                                 "-p", "auto_identify:=false")
    processes = (driver, notch)
    node = ros_context.create_node("hostile_accel")
    accel, command = StrutTopic(node, "/pph/accel"), StrutTopic(node, "/pph/notch_command")
    diagnostics = Diagnostics(node)
    to_notch = node.create_publisher(Float64MultiArray, "/pph/accel",
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    rounds = itertools.count()

    def logs() -> str:
        return "\n".join(p.output() for p in processes)

    def send_hostile() -> None:
        """One round every 5 spins: refusal is tested here, floods in test_flood.py."""
        round_ = next(rounds)
        if round_ % 5 == 0:
            for raw in _hostile_eddy(max(accel.last_index, 0), round_ // 5):
                to_notch.publish(raw)

    def counted() -> bool:
        values = diagnostics.values(NOTCH_STATUS)
        return all(int(values.get(k, 0)) > 0 for k in ("malformed", "out_of_range"))

    assert wait_until(ros_context, lambda: not all(p.running() for p in processes) or (
        counted() and command.last_index > 2000), step=send_hostile), logs()
    assert all(p.running() for p in processes), logs()
    # The raw canceller (P = I, mu = 1e-5) on the real +-2 g accelerations: its commands stay
    # of the order of mu * n * a (a few N); one 1e300 sample would have made them ~1e295.
    peak = max(np.max(np.abs(c)) for c in command.by_index.values())
    assert peak < 40.0, peak
    for process in processes:
        assert process.stop() == 130, process.output()     # SIGINT: 128 + 2
