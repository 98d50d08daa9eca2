"""Outputs complete or absent: tools/outputs, and ``analyze`` interrupted in the middle."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.analysis.bag_writer import write_strut_bag
from hexapod_vibration.tools import outputs

HANG_GUARD_S = 120.0


def test_write_text_replaces_atomically(tmp_path):
    path = outputs.write_text(tmp_path / "a" / "params.yaml", "one\n")
    assert path.read_text() == "one\n"
    outputs.write_text(path, "two\n")
    assert path.read_text() == "two\n"
    assert [p.name for p in path.parent.iterdir()] == ["params.yaml"]


def test_staged_publishes_only_on_success(tmp_path):
    out = tmp_path / "report"
    with pytest.raises(RuntimeError), outputs.staged(out) as staging:
        (staging / "report.json").write_text("{}")
        raise RuntimeError("interrupted")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with outputs.staged(out) as staging:
        (staging / "report.json").write_text('{"a": 1}')
        (staging / "plots").mkdir()
        (staging / "plots" / "x.png").write_bytes(b"png")
    assert (out / "report.json").read_text() == '{"a": 1}'
    assert (out / "plots" / "x.png").read_bytes() == b"png"
    # Into an existing folder (the experiment's): other files are kept, ours replaced.
    (out / "bag").mkdir()
    with outputs.staged(out) as staging:
        (staging / "report.json").write_text('{"a": 2}')
    assert (out / "report.json").read_text() == '{"a": 2}' and (out / "bag").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_analyze_leaves_no_half_written_folder(tmp_path, signum):
    n = 60_000
    t = np.arange(n) / 1000.0
    accel = np.zeros((n, 6)) + 9.8
    accel += 0.1 * np.sin(2 * np.pi * 40.0 * t)[:, None]
    accel += np.random.default_rng(0).normal(0, 1e-3, accel.shape)
    bag = write_strut_bag(tmp_path / "bag", {"/pph/accel": (np.arange(n), accel)})
    out = tmp_path / "report"
    process = subprocess.Popen([str(Path(sys.executable).parent / "analyze"), str(bag),
                                "--out", str(out)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + HANG_GUARD_S
    while not out.exists() and not list(tmp_path.glob(".report.partial-*")):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=HANG_GUARD_S)
    if process.returncode == 0:       # it finished first: then the folder is complete
        assert (out / "report.json").is_file() and (out / "spectra.png").is_file()
        pytest.skip("analyze finished before the signal")
    assert process.returncode == 128 + signum, stderr
    assert "Traceback" not in stderr, stderr
    assert not out.exists()
    assert not list(tmp_path.glob(".report.partial-*"))
