"""Which arithmetic steps the core per sample: compiled kernels (numba) or NumPy.

Both give the same numbers (:mod:`~hexapod_vibration.core.model.compiled_sample` for the
simulated hexapod, :mod:`~hexapod_vibration.core.control.compiled_law` for the pointing
law, :mod:`~hexapod_vibration.core.control.compiled_continuation` for its forecast, to within
1e-9 N); the compiled kernels take a fraction of the time per sample. numba is an optional
dependency: without it, or with ``HEXAPOD_VIBRATION_KERNELS=numpy`` in the environment, the
plant, its shaker and accelerometers, the pointing law and its forecast run their NumPy code.
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType

KERNELS_ENV = "HEXAPOD_VIBRATION_KERNELS"
"""Environment variable: ``numpy`` runs the NumPy path even where numba is installed."""


def compiled_kernels() -> ModuleType | None:
    """The plant's compiled kernels, or None for the NumPy path (numba missing, or asked)."""
    return _compiled("hexapod_vibration.core.model.compiled_sample")


def compiled_law_kernels() -> ModuleType | None:
    """The pointing law's compiled kernels, or None for the NumPy path (as the plant's)."""
    return _compiled("hexapod_vibration.core.control.compiled_law")


def compiled_continuation_kernels() -> ModuleType | None:
    """The tone continuation's compiled kernel, or None for the NumPy path (as the plant's)."""
    return _compiled("hexapod_vibration.core.control.compiled_continuation")


def _compiled(module: str) -> ModuleType | None:
    """The kernels' module ``module``, imported (compiled) on first use; None: NumPy."""
    if os.environ.get(KERNELS_ENV, "").strip().lower() == "numpy":
        return None
    try:
        return importlib.import_module(module)
    except (ImportError, RuntimeError):   # no numba, or its cache has no writable place
        return None


def kernels_name(kernels: ModuleType | None) -> str:
    """``compiled`` or ``numpy``: what a report says steps the plant or the law."""
    return "numpy" if kernels is None else "compiled"
