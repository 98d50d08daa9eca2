"""Which Python code runs inside compiled kernels: none may (a Ctrl-C must not land there).

A kernel that returned an array ran numba's ``_numba_unpickle`` (Python) to box it; a Ctrl-C
there raised the nodes' StopSignal inside the kernel, which numba turned into a SystemError.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable


def numba_files_called(action: Callable[[], object]) -> list[str]:
    """The files of the numba package whose Python functions ran during ``action()``."""
    calls: set[str] = set()

    def note(frame, event, _arg):
        if event == "call":
            calls.add(frame.f_code.co_filename)

    previous = sys.getprofile()
    sys.setprofile(note)
    try:
        action()
    finally:
        sys.setprofile(previous)
    return [name for name in calls if f"{os.sep}numba{os.sep}" in name]
