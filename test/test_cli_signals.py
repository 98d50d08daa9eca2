"""cli's stop handling: an object a stop signal cut short prints nothing when collected.

Each case runs in its own interpreter (signal handlers and ``sys.unraisablehook`` are per
process); the half-built object stands for rclpy's executor ``Task``, whose ``__del__``
reads an attribute its ``__init__`` sets.
"""

import subprocess
import sys
import textwrap

import pytest

CASE = textwrap.dedent("""
    import os, signal
    from hexapod_vibration import cli

    class HalfBuilt:
        def __del__(self):
            if self._exception is not None:      # set by an __init__ that never ran
                pass

    cli.install_stop_handlers()
    if {stop}:
        try:
            os.kill(os.getpid(), signal.SIGINT)
            signal.pause()
        except cli.StopSignal:
            pass
    obj = HalfBuilt.__new__(HalfBuilt)
    del obj
    {other}
    print("end", flush=True)
""")


def _run(stop: bool, other: str = "") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", CASE.format(stop=stop, other=other)],
                          capture_output=True, text=True, timeout=60)


def test_a_half_built_objects_finalizer_is_quiet_after_a_stop():
    result = _run(stop=True)
    assert result.returncode == 0 and result.stdout == "end\n", result.stderr
    assert result.stderr == ""


@pytest.mark.parametrize("case", ["no stop", "another error"])
def test_other_finalizer_errors_are_still_printed(case):
    other = ("" if case == "no stop" else textwrap.dedent("""
        class Broken:
            def __del__(self):
                raise ValueError("a real bug")
        b = Broken(); del b"""))
    result = _run(stop=case != "no stop", other=other)
    assert result.stdout == "end\n"
    expected = "AttributeError" if case == "no stop" else "ValueError: a real bug"
    assert "Exception ignored in" in result.stderr and expected in result.stderr, result.stderr
