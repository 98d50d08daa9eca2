"""The three nodes from their executables: contract topics, sample pairing, closed loop.

pph_driver (lockstep), notch_controller and pointing_controller run as separate processes
on the test's own ROS domain; the test process listens on every contract topic. The
closed loop is judged on the data only (the 40 Hz amplitude of /pph/accel before the
controller identified the plant versus after it converged), never on timing.
"""

from __future__ import annotations

import numpy as np
from node_graph import (
    HANG_GUARD_S,
    STRUT_TOPICS,
    ClockTopic,
    Diagnostics,
    StrutTopic,
    db,
    tone_amplitude,
)

from hexapod_vibration.core.model_config import load_model_config
from hexapod_vibration.core.plant import saturate_commands
from hexapod_vibration.paths import config_path

TONE_HZ = 40.0
IDENTIFY_DELAY_S = 1.0
MU = 0.01
CONVERGED_AFTER_SAMPLES = 1000   # 10 time constants of mu = 0.01 (per sample)
WINDOW_SAMPLES = 1000            # 40 periods of the tone
MIN_REDUCTION_DB = 20.0


def test_nodes_exchange_contract_topics_and_cancel_the_tone(ros_context, node_processes):
    driver = node_processes.start(
        'pph_driver', '--ros-args', '-p', 'clock_mode:=lockstep',
        '-p', f'shaker_frequencies_hz:=[{TONE_HZ}]', '-p', 'shaker_amplitudes_n:=[80.0]')
    notch = node_processes.start(
        'notch_controller', '--ros-args', '-p', f'tone_frequencies_hz:=[{TONE_HZ}]',
        '-p', f'mu:={MU}', '-p', f'identify_delay_s:={IDENTIFY_DELAY_S}')
    pointing = node_processes.start('pointing_controller')
    processes = (driver, notch, pointing)

    def logs() -> str:
        return '\n'.join(p.output() for p in processes)

    node = ros_context.create_node('bringup_listener')
    topics = {name: StrutTopic(node, name) for name in STRUT_TOPICS}
    clock = ClockTopic(node)
    diagnostics = Diagnostics(node)
    accel = topics['/pph/accel']

    def notch_state() -> str:
        return diagnostics.value('notch_controller', 'state')

    # The controller identifies the plant after IDENTIFY_DELAY_S of samples, then adapts.
    adapting = ros_context.wait_for(
        lambda: notch_state() == 'adapting' or not all(p.running() for p in processes),
        HANG_GUARD_S)
    assert adapting and notch_state() == 'adapting', logs()
    enabled_since = diagnostics.int_value('notch_controller', 'enabled_since_sample')
    assert enabled_since > IDENTIFY_DELAY_S * 1000, diagnostics.values('notch_controller')
    end = enabled_since + CONVERGED_AFTER_SAMPLES + WINDOW_SAMPLES
    done = ros_context.wait_for(
        lambda: accel.last_index >= end + 10 and diagnostics.value('pph_driver: loop', 'sample')
        not in ('', '0') or not all(p.running() for p in processes), HANG_GUARD_S)
    assert done and all(p.running() for p in processes), logs()

    # Every contract topic: six values, layout.dim[0] = ("strut", 6, 6), in-band index.
    for name, topic in topics.items():
        msg = topic.first_message
        assert msg is not None, f'nothing on {name}'
        dim = msg.layout.dim[0]
        assert (dim.label, dim.size, dim.stride) == ('strut', 6, 6), name
        assert len(msg.data) == 6 and msg.layout.dim[1].label.startswith('sample:'), name
        assert topic.unindexed == 0, name
        assert len(topic.by_index) > 1000, (name, len(topic.by_index))
    # /clock is the sim time of the samples: n ms.
    assert len(clock.times_ns) > 100
    assert all(t % 1_000_000 == 0 for t in clock.times_ns)
    assert max(clock.times_ns) >= 1_000_000 * (end - 1000)
    # /diagnostics from every node.
    for name in ('pph_driver: loop', 'notch_controller', 'pointing_controller'):
        assert name in diagnostics.latest, (name, sorted(diagnostics.latest))
    assert diagnostics.value('pph_driver: loop', 'mode') == 'lockstep'
    # Raw accelerometers: gravity (DC) included.
    _, raw = accel.window(0, end)
    assert np.all(np.abs(raw.mean(axis=0)) > 1.0), raw.mean(axis=0)

    # Lockstep pairs the commands with the samples: what the driver applied at sample n is
    # the saturated sum of both controllers' commands for sample n.
    strut = load_model_config(config_path('pph_model.yaml')).strut
    notch_cmd, pointing_cmd = topics['/pph/notch_command'], topics['/pph/pointing_command']
    force = topics['/pph/actuator_force']
    paired = sorted(set(force.by_index) & set(notch_cmd.by_index) & set(pointing_cmd.by_index))
    assert len(paired) > 1000
    for n in paired:
        expected = saturate_commands(notch_cmd.by_index[n], pointing_cmd.by_index[n], strut)
        np.testing.assert_allclose(force.by_index[n], expected, rtol=0, atol=1e-12,
                                   err_msg=f'sample {n}')
    # The notch controller's output is on (and not trivial) once it adapts.
    _, late_notch = notch_cmd.window(enabled_since + CONVERGED_AFTER_SAMPLES, end)
    assert np.max(np.abs(late_notch)) > 0.1

    # Closed loop: the 40 Hz component of the accelerometers, control off vs converged.
    off_idx, off = accel.window(200, int(IDENTIFY_DELAY_S * 1000))
    on_idx, on = accel.window(end - WINDOW_SAMPLES, end)
    assert off_idx.size > 0.9 * (IDENTIFY_DELAY_S * 1000 - 200) and on_idx.size > 900
    before = tone_amplitude(off_idx, off, TONE_HZ)
    after = tone_amplitude(on_idx, on, TONE_HZ)
    reduction_db = db(np.linalg.norm(before) / np.linalg.norm(after))
    print(f'40 Hz accel amplitude per strut before {np.round(before, 4)} m/s^2, after '
          f'{np.round(after, 5)} m/s^2: reduction {reduction_db:.1f} dB; driver '
          f'{diagnostics.values("pph_driver: loop")}')
    assert np.all(before > 0.05), before    # tens of mg: the shaker is on
    assert reduction_db > MIN_REDUCTION_DB, (before, after)
    for process in processes:
        assert process.stop() == 0, process.output()
