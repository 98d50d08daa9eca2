"""The machine a benchmark ran on: processor, cores, load, Python and library versions.

Also what steps the simulated plant there (``plant_kernels``: ``compiled`` or ``numpy``, the
same numbers at different costs; the nodes the bench starts inherit its environment, so they
choose as it does).
"""

from __future__ import annotations

import os
import platform
from typing import Any

import numpy as np

from hexapod_vibration.core.model.kernel_choice import compiled_kernels, kernels_name


def machine_info() -> dict[str, Any]:
    """Processor, CPU model, cores, load, Python and numpy versions, the plant's kernels."""
    model = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as stream:
            for line in stream:
                if line.lower().startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    uname = platform.uname()
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count() or 0
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = []
    import scipy

    return {
        "processor": platform.processor() or uname.machine,
        "uname": f"{uname.system} {uname.release} {uname.machine}",
        "cpu_model": model or "unknown",
        "cpu_count": os.cpu_count() or 0,
        "cpu_usable": usable,
        "load_average_1_5_15": load,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "plant_kernels": kernels_name(compiled_kernels()),
    }


def machine_summary(info: dict[str, Any]) -> str:
    """One line naming the machine of :func:`machine_info` (``results.json``'s ``machine``)."""
    return (f"{info['cpu_model']} ({info['processor']}), {info['cpu_count']} cores "
            f"({info['cpu_usable']} usable), {info['uname']}, Python {info['python']}, "
            f"numpy {info['numpy']}, scipy {info['scipy']}, plant kernels {info['plant_kernels']}, "
            f"load {info['load_average_1_5_15']}")
