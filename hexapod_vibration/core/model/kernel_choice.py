"""Which arithmetic steps the simulated hexapod: compiled kernels (numba) or NumPy.

Both give the same numbers (:mod:`~hexapod_vibration.core.model.compiled_sample`); the
compiled kernels take a fraction of the time per sample. numba is an optional dependency:
without it, or with ``HEXAPOD_VIBRATION_KERNELS=numpy`` in the environment, the plant,
its shaker and its accelerometers run their NumPy code.
"""

from __future__ import annotations

import os
from types import ModuleType

KERNELS_ENV = "HEXAPOD_VIBRATION_KERNELS"
"""Environment variable: ``numpy`` runs the NumPy path even where numba is installed."""


def compiled_kernels() -> ModuleType | None:
    """The compiled kernels' module, or None for the NumPy path (numba missing, or asked)."""
    if os.environ.get(KERNELS_ENV, "").strip().lower() == "numpy":
        return None
    try:
        from hexapod_vibration.core.model import compiled_sample
    except (ImportError, RuntimeError):   # no numba, or its cache has no writable place
        return None
    return compiled_sample


def kernels_name(kernels: ModuleType | None) -> str:
    """``compiled`` or ``numpy``: what a report says steps the plant."""
    return "numpy" if kernels is None else "compiled"
