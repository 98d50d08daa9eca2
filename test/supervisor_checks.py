"""Assertions on a notch supervisor shared by the core tests."""

from __future__ import annotations

import pytest

from hexapod_vibration.core.control.notch_supervisor import NotchSupervisor


def assert_refused_and_unchanged(sup: NotchSupervisor, changes: dict, reason: str) -> None:
    """``check`` and ``apply`` refuse ``changes`` with ``reason`` (a regex); nothing changed."""
    before = sup.config
    with pytest.raises(ValueError, match=reason):
        sup.check(changes)
    with pytest.raises(ValueError, match=reason):
        sup.apply(changes)
    assert sup.config == before
