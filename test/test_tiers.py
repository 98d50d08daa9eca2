"""The test tiers of ``test/conftest.py``: one tier per test, and no rclpy for pure tests.

Each check collects the suite in a separate pytest process (a plugin in the test's folder
records what the conftest gave every test), as ``make check`` and ``make test`` collect it.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIERS = ("unit", "scenario", "graph")
HANG_GUARD_S = 300.0
PLUGIN = """
import json, os

import pytest


def pytest_sessionstart(session):
    extra = os.environ.get('EXTRA_SCENARIO')
    if extra:                      # a name that matches no test, as after a rename
        for plugin in session.config.pluginmanager.get_plugins():
            if hasattr(plugin, 'SCENARIO_TESTS'):
                plugin.SCENARIO_TESTS = (*plugin.SCENARIO_TESTS, extra)


def pytest_collection_finish(session):
    marks = {item.nodeid: sorted({m.name for m in item.iter_markers()}) for item in session.items}
    with open(os.environ['TIERS_OUT'], 'w') as stream:
        json.dump(marks, stream)
"""


def collect(tmp_path: Path, path: str, python_options: tuple[str, ...] = (),
            run: bool = False, **env: str) -> tuple[subprocess.CompletedProcess, dict]:
    """``pytest --collect-only PATH`` (or a run) with the marker-recording plugin.

    Returns:
        The finished process, and the markers of every collected test by node id.
    """
    (tmp_path / "record_tiers.py").write_text(PLUGIN)
    out = tmp_path / "tiers.json"
    environ = dict(os.environ, PYTHONPATH=str(tmp_path), TIERS_OUT=str(out), **env)
    only = () if run else ("--collect-only",)
    result = subprocess.run([sys.executable, *python_options, "-m", "pytest", "-q", *only,
                             "-p", "record_tiers", "-p", "no:cacheprovider", path],
                            cwd=ROOT, env=environ, capture_output=True, text=True,
                            timeout=HANG_GUARD_S)
    return result, json.loads(out.read_text()) if out.exists() else {}


def test_every_test_is_in_exactly_one_tier(tmp_path):
    result, marks = collect(tmp_path, "test")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert len(marks) > 700
    for nodeid, names in marks.items():
        tiers = [t for t in TIERS if t in names]
        assert len(tiers) == 1, (nodeid, names)
        assert ("ros" in names) == (tiers == ["graph"]), (nodeid, names)
    tier_of = {nodeid: next(t for t in TIERS if t in names) for nodeid, names in marks.items()}
    for prefix, tier in (("test/nodes/test_parameters_nodes.py::", "graph"),
                         ("test/core/test_never_worse_core_loop.py::", "scenario"),
                         ("test/core/test_phasor.py::", "unit"),
                         ("test/test_tiers.py::", "unit")):
        matched = [t for nodeid, t in tier_of.items() if nodeid.startswith(prefix)]
        assert matched and set(matched) == {tier}, (prefix, matched)


def test_a_scenario_entry_that_names_no_test_stops_the_whole_suite(tmp_path):
    result, _ = collect(tmp_path, "test", EXTRA_SCENARIO="test_gone.py")
    assert result.returncode != 0
    assert "SCENARIO_TESTS in test/conftest.py names no test: test_gone.py" in (
        result.stdout + result.stderr), result.stdout[-2000:] + result.stderr[-2000:]


def test_pure_tests_are_collected_and_run_without_rclpy(tmp_path):
    result, marks = collect(tmp_path, "test/core/test_phasor.py", ("-X", "importtime"), run=True)
    assert result.returncode == 0 and " passed" in result.stdout, result.stderr[-3000:]
    assert marks and all("unit" in names for names in marks.values())
    imported = set(re.findall(r"import time:\s+\d+ \|\s+\d+ \|\s*(\w+)", result.stderr))
    assert "pytest" in imported and "rclpy" not in imported
