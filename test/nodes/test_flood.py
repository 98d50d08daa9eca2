"""A flood of invalid commands does not cost lockstep a legitimate one.

Old driver: 20 000 invalid messages at 12-17 kHz pushed the real lockstep command out of its
10-deep subscription queue, and the loop stalled for ``lockstep_timeout_s`` (2 s) per lost
command. Now a sample whose commands are missing is offered again after 50 ms and the
controller answers the repeat with the same command, so nothing depends on queue depth.
The flood comes from its own process (as fast as rclpy publishes), on the pointing
controller's topic; judged on the driver's counts and the data of every sample.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from node_graph import HANG_GUARD_S, Diagnostics, StrutTopic, start_pointing_loop, wait_until

from hexapod_vibration.contract import DRIVER_STATUS
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.core.model.plant import saturate_commands
from hexapod_vibration.paths import config_path

STRUT = load_model_config(config_path("pph_model.yaml")).strut
FLOOD_MESSAGES = 20000
AFTER_SAMPLES = 1000

FLOODER = f"""
import time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from rclpy.serialization import serialize_message

rclpy.init()
node = rclpy.create_node('flooder')
pub = node.create_publisher(Float64MultiArray, '/pph/pointing_command',
                            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
raw = serialize_message(Float64MultiArray(data=[1.0] * 5))   # five values: invalid
deadline = time.monotonic() + 60.0
while pub.get_subscription_count() < 2 and time.monotonic() < deadline:
    time.sleep(0.05)
start = time.monotonic()
for _ in range({FLOOD_MESSAGES}):
    pub.publish(raw)
print(f'sent {FLOOD_MESSAGES} in {{time.monotonic() - start:.3f}} s', flush=True)
time.sleep(1.0)   # RELIABLE: the writer's history is delivered before it is destroyed
node.destroy_node()
rclpy.shutdown()
"""


def test_flood_of_invalid_commands_loses_no_lockstep_command(ros_context, node_processes,
                                                            ros_env):
    # A lockstep timeout far beyond the flood: on a loaded machine (a full test run) its
    # delivery once lasted 2.3 s, past the default 2 s, while re-offers (every 50 ms) are
    # what must bring the command back.
    driver, pointing = start_pointing_loop(node_processes, "-p", "lockstep_timeout_s:=10.0")
    node = ros_context.create_node("flood_listener")
    commands = StrutTopic(node, "/pph/pointing_command")
    force = StrutTopic(node, "/pph/actuator_force")
    diagnostics = Diagnostics(node)

    def logs() -> str:
        return "\n".join(p.output() for p in (driver, pointing))

    assert wait_until(ros_context, lambda: force.last_index > 200
                      and DRIVER_STATUS in diagnostics.latest), logs()
    run = diagnostics.value(DRIVER_STATUS, "run")
    run = int(run) if run else None       # a driver without runs (older code)
    flood_start = force.last_index
    flooder = subprocess.Popen([sys.executable, "-c", FLOODER], env=ros_env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert wait_until(ros_context, lambda: flooder.poll() is not None, HANG_GUARD_S)
    finally:
        if flooder.poll() is None:
            flooder.kill()
        out, err = flooder.communicate()
    assert flooder.returncode == 0, err
    flood_end = force.last_index
    reported = len(diagnostics.history_values(DRIVER_STATUS))

    def reported_after() -> dict[str, str] | None:
        later = [v for v in diagnostics.history_values(DRIVER_STATUS)[reported:]
                 if int(v["sample"]) > flood_end + AFTER_SAMPLES]
        return later[0] if later else None

    assert wait_until(ros_context, lambda: reported_after() is not None), logs()
    values = reported_after()
    print(f'{out.strip()}; samples {flood_start}..{flood_end} during the flood; driver {values}; '
          f'pointing {diagnostics.values("pointing_controller")}')
    assert int(values.get("pointing_malformed", values["pointing_invalid"])) > 0   # reached it
    assert int(values["timeouts"]) == 0, values           # no command lost for good
    assert int(values["missed_samples"]) == 0, values
    # Every sample (seen here) applied the pointing command of that very sample.
    ours, applied = commands.by_run[run], force.by_run[run]
    window = [n for n in range(flood_start, flood_end + AFTER_SAMPLES)
              if n in ours and n in applied]
    # The driver's counts above prove no sample went without its command; this listener
    # (a loaded test process) may not see every message, so the data is checked where seen.
    assert len(window) >= AFTER_SAMPLES // 2, len(window)
    for n in window:
        np.testing.assert_allclose(applied[n], saturate_commands(np.zeros(6), ours[n], STRUT),
                                   rtol=0, atol=1e-12, err_msg=str(n))
    assert driver.running() and pointing.running()
    for process in (driver, pointing):
        assert process.stop() == 130, process.output()     # SIGINT: 128 + 2
