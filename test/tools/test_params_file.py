"""``params.yaml`` written by ``experiment`` starts the same run through the launch file.

The launch file starts each node with ``parameters=[params_file, {'clock_mode': ...}]``,
that is ``--ros-args --params-file params.yaml -p clock_mode:=<mode>`` (launch_ros writes
the dict into a second params file). Started that way from the experiment's params.yaml,
the lockstep graph produces, sample for sample, the accelerations the experiment recorded
before its control-on switch: same seed, same shaker, same controllers (the README's
params.yaml header says what the runner did on top: the breakpoints and the switch).
"""

from __future__ import annotations

import numpy as np
import yaml
from node_graph import HANG_GUARD_S, ParameterClient, StrutTopic, run_experiment, wait_until

from hexapod_vibration.analysis.bag_reading import read_strut_topics

SCENARIO = {
    "name": "params_reuse", "seed": 7, "duration_s": 6.5, "identify_at_s": 0.2,
    "control_on_s": 5.5, "window_s": 1.0,
    "shaker": {"frequencies_hz": [40.0, 80.0], "amplitudes_n": [80.0, 16.0],
               "noise_rms_n": 0.5},
    "notch": {"preset": "paper", "tone_frequencies_hz": [40.0], "mu": 0.01,
              "adaptation": "decentralized"},            # test tones: a short timeline
}
COMPARED = 3000     # samples before control-on (5500)
MATCHED_BY_SAMPLE = 200
"""The relaunched driver holds here (``hold_at_time_s``, a lockstep breakpoint: the samples
are the same) until this test's listener matched it: alone with two controllers the loop
runs at ~3 kHz, faster than discovery on a loaded machine (the listener would miss most
of the 3000 compared samples)."""


def test_params_yaml_starts_the_same_run(ros_env, ros_context, node_processes, tmp_path):
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump(SCENARIO))
    out = tmp_path / "run"
    result = run_experiment(ros_env, scenario, out, "--no-plots", timeout=600)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    params_file = out / "params.yaml"
    text = params_file.read_text()
    assert "ros2 launch hexapod_vibration pph.launch.py params_file:=" in text
    params = yaml.safe_load(text)
    assert "hold_at_time_s" not in params["pph_driver"]["ros__parameters"]
    recorded = read_strut_topics(out / "bag")["/pph/accel"]

    # The launch file's command lines, from the params file alone.
    node = ros_context.create_node("listener")
    accel = StrutTopic(node, "/pph/accel")
    common = ["--ros-args", "--params-file", str(params_file)]
    for name in ("notch_controller", "pointing_controller"):
        node_processes.start(name, *common)
    driver = node_processes.start("pph_driver", *common, "-p", "clock_mode:=lockstep",
                                  "-p", f"hold_at_time_s:={MATCHED_BY_SAMPLE / 1000.0}")
    assert wait_until(ros_context, lambda: not driver.running()
                      or accel.subscription.get_publisher_count() >= 1, HANG_GUARD_S), \
        driver.output()
    driver_params = ParameterClient(ros_context, node, "pph_driver")
    assert driver_params.set("hold_at_time_s", (COMPARED + 100) / 1000.0).successful
    assert wait_until(ros_context, lambda: accel.last_index >= COMPARED, HANG_GUARD_S), \
        driver.output()
    # Every sample this listener received before COMPARED must be the recorded one, bit
    # for bit (the first ones may have gone out before it matched the driver).
    idx, values = accel.window(0, COMPARED)
    print(f"listener received {len(idx)} of the {COMPARED} compared samples")
    assert len(idx) >= COMPARED // 2, len(idx)
    assert np.all(np.diff(idx) == 1), "a gap in the middle of the stream"
    assert np.array_equal(recorded.sample_index[:COMPARED], np.arange(COMPARED))
    assert np.array_equal(recorded.values[idx], values)
