"""Fixtures of the core's tests."""

from __future__ import annotations

import pytest

from hexapod_vibration.core.model.kernel_choice import KERNELS_ENV


@pytest.fixture(params=["compiled", "numpy"])
def kernels(request, monkeypatch):
    """Build a test's plants, filters and laws on the compiled kernels or on the NumPy path."""
    if request.param == "compiled":
        pytest.importorskip("numba")
    monkeypatch.setenv(KERNELS_ENV, request.param)
    return request.param
