"""No process outlives its parent: tools/processes, and the experiment killed with SIGKILL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import yaml
from process_tree import alive, children_of, command_of, wait_gone
from rosbags.rosbag2 import Reader

HANG_GUARD_S = 90.0
ROOT = Path(__file__).resolve().parents[2]


def test_a_child_dies_with_its_parent_even_on_sigkill(tmp_path):
    """A parent spawns a sleeper through tools/processes and is SIGKILLed: the sleeper goes."""
    script = textwrap.dedent(f"""
        import sys, time
        from hexapod_vibration.tools.processes import spawn
        child = spawn("sleeper", ["sleep", "1000"], log={str(tmp_path / 'sleep.log')!r})
        print(child.pid, flush=True)
        time.sleep(1000)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    sleeper = int(parent.stdout.readline())
    assert alive(sleeper)
    assert os.getpgid(sleeper) == sleeper              # its own process group
    parent.kill()
    parent.wait()
    assert wait_gone([sleeper]) == []


def test_stop_kills_the_group_of_a_stuck_child(tmp_path):
    from hexapod_vibration.tools.processes import spawn

    child = spawn("stubborn", [sys.executable, "-c",
                              'import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN);'
                              ' print("ready", flush=True); time.sleep(1000)'],
                  log=tmp_path / "stubborn.log")
    deadline = time.monotonic() + HANG_GUARD_S
    while "ready" not in (tmp_path / "stubborn.log").read_text():
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert child.stop(timeout_s=0.5) == -signal.SIGKILL
    assert not alive(child.pid)


def test_sigkill_of_the_experiment_leaves_no_process_and_a_readable_bag(ros_env, tmp_path):
    scenario = tmp_path / "long.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": "long", "seed": 3, "duration_s": 600.0, "identify_at_s": 0.2,
        "control_on_s": 300.0, "window_s": 2.0,
        "shaker": {"frequencies_hz": [40.0], "amplitudes_n": [80.0]},
        "notch": {"tone_frequencies_hz": [40.0], "mu": 0.01}}))
    out = tmp_path / "run"
    runner = subprocess.Popen([sys.executable, "-m", "hexapod_vibration.tools.experiment",
                               "--scenario", str(scenario), "--out", str(out)], env=ros_env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + HANG_GUARD_S * 2
        while True:                          # until the run is recording samples
            mcap = list((out / "bag").glob("*.mcap")) if (out / "bag").exists() else []
            if mcap and mcap[0].stat().st_size > 100_000:
                break
            assert runner.poll() is None, "the experiment ended early"
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.5)
        children = children_of(runner.pid)
        assert len(children) == 4, children          # recorder, notch, pointing, driver
        names = {pid: command_of(pid) for pid in children}
        runner.kill()
        runner.wait()
        left = wait_gone(children)
        assert left == [], f"children outlived the experiment: {[names[p] for p in left]}"
    finally:
        if runner.poll() is None:
            runner.kill()
    with Reader(out / "bag") as reader:       # the recorder got SIGTERM and closed the bag
        assert reader.message_count > 0
    assert (out / "bag" / "metadata.yaml").is_file()
