"""Everything below rclpy's public API, in one module.

The 1 kHz loop avoids rclpy's conversion between Python messages and their C form, which
costs more than a message's whole DDS delivery within a process. Its messages travel as
CDR bytes (written and read by :mod:`hexapod_vibration.cdr`, no rclpy), which takes four
things rclpy does not offer publicly:

- a persistent wait set over the loop subscriptions (``rclpy_implementation.WaitSet``);
- taking a subscription's queued messages serialized, directly from its handle
  (``Subscription.handle.take_message``), as rclpy's executors do internally;
- publishing serialized bytes without rclpy's per-call type check
  (``Publisher.handle.publish_raw``);
- ``RCLError``, what those calls raise (``rclpy._rclpy_pybind11``).

These were verified against rclpy :data:`VERIFIED_RCLPY_VERSION`. With another version,
with one of the private APIs missing, or with ``HEXAPOD_RCLPY_PUBLIC_API=1`` in the
environment, :func:`fast_path` is False and the callers use the public API instead
(rclpy's executor for the loop subscriptions, ``Publisher.publish``), which is slower but
has the same results; the reason is logged once per process.
"""

from __future__ import annotations

import functools
import importlib.metadata
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import rclpy.logging
from rclpy.exceptions import InvalidHandle

VERIFIED_RCLPY_VERSION = "7.1.6"
"""The rclpy release whose private APIs this module was verified against."""

PUBLIC_API_ENV = "HEXAPOD_RCLPY_PUBLIC_API"
"""Environment variable: set to 1 to use only rclpy's public API."""

_RCLPY_DISTRIBUTIONS = ("ros-jazzy-rclpy", "ros-rclpy")
"""PyPI distributions of rclpy (the README's set-up); apt installs have the ament index."""

try:
    from rclpy._rclpy_pybind11 import RCLError
except ImportError:             # pragma: no cover - another rclpy layout
    RCLError = RuntimeError     # what it derives from

RCL_ERRORS = (RuntimeError, InvalidHandle)
"""What an rcl call on a destroyed entity or a shut-down context raises (RCLError included)."""


def parameter_overrides(node: Any) -> dict[str, Any]:
    """The parameter values given to ``node`` at start-up (``-p``, params files), by name.

    rclpy keeps them in the private ``Node._parameter_overrides`` (verified with 7.1.6);
    without it, an empty mapping: unknown parameters then go unreported.
    """
    return dict(getattr(node, "_parameter_overrides", {}))


# ---------------------------------------------------------------------------- version check
def rclpy_version() -> str | None:
    """The installed rclpy's version (PyPI distribution or ament index), None if unknown."""
    for name in _RCLPY_DISTRIBUTIONS:
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    try:
        from ament_index_python.packages import get_package_share_directory

        xml = Path(get_package_share_directory("rclpy"), "package.xml").read_text()
    except Exception:           # noqa: BLE001 - no ament index, no rclpy share: unknown
        return None
    match = re.search(r"<version>\s*([^<\s]+)\s*</version>", xml)
    return match.group(1) if match else None


def _missing_api() -> str:
    """The first private API this module needs that rclpy lacks ("" if none)."""
    try:
        from rclpy.impl.implementation_singleton import rclpy_implementation as impl
    except ImportError:
        return "rclpy.impl.implementation_singleton"
    needed = {"WaitSet": ("clear_entities", "add_subscription", "wait", "get_ready_entities"),
              "Subscription": ("take_message",), "Publisher": ("publish_raw",)}
    for cls, methods in needed.items():
        for method in methods:
            if not hasattr(getattr(impl, cls, None), method):
                return f"{cls}.{method}"
    return "" if RCLError is not RuntimeError else "_rclpy_pybind11.RCLError"


@functools.cache
def fast_path_problem() -> str:
    """Why the private fast path is not used ("" when it is)."""
    if os.environ.get(PUBLIC_API_ENV, "") not in ("", "0"):
        return f"{PUBLIC_API_ENV} is set"
    version = rclpy_version()
    if version != VERIFIED_RCLPY_VERSION:
        return f"rclpy {version or '(unknown version)'} is not {VERIFIED_RCLPY_VERSION}"
    missing = _missing_api()
    return f"rclpy lacks {missing}" if missing else ""


@functools.cache
def fast_path() -> bool:
    """Whether the private fast path is used; logs once why not."""
    problem = fast_path_problem()
    if problem:
        rclpy.logging.get_logger("hexapod_vibration").warning(
            f"{problem}: using rclpy's public API for the loop (slower, same results)")
    return not problem


# ---------------------------------------------------------------------------- private API
class LoopWaitSet:
    """A persistent rcl wait set over a node's loop subscriptions (fast path only)."""

    def __init__(self, context: Any, subscriptions: Sequence[Any]) -> None:
        """Allocate the wait set for ``subscriptions`` in ``context`` (an rclpy Context)."""
        from rclpy.impl.implementation_singleton import rclpy_implementation as impl

        self.subscriptions = list(subscriptions)
        self._handles = [sub.handle for sub in self.subscriptions]
        self._by_pointer = {sub.handle.pointer: sub for sub in self.subscriptions}
        self._wait_set = impl.WaitSet(len(self.subscriptions), 0, 0, 0, 0, 0, context.handle)

    def wait(self, timeout_s: float) -> list[Any]:
        """The subscriptions with data, waiting up to ``timeout_s`` (0: a poll) for one.

        Data queued before the call counts: rcl returns at once then.
        """
        wait_set = self._wait_set
        wait_set.clear_entities()
        for handle in self._handles:
            wait_set.add_subscription(handle)
        wait_set.wait(int(timeout_s * 1e9))
        by_pointer = self._by_pointer
        return [by_pointer[p] for p in wait_set.get_ready_entities("subscription")]


def take_serialized(subscription: Any) -> bytes | None:
    """One queued message of ``subscription`` as CDR bytes, None if none (fast path only).

    Without rclpy's destruction guard (``with subscription.handle``): the loop that takes
    runs in the node's thread, which destroys the node only after the loop ended.
    """
    taken = subscription.handle.take_message(subscription.msg_type, True)
    return None if taken is None else taken[0]


def take_serialized_batch(subscription: Any, limit: int) -> list[bytes]:
    """Up to ``limit`` queued messages as CDR bytes; [] on the public path (executor's job)."""
    if not fast_path():
        return []
    taken = []
    with subscription.handle:
        for _ in range(limit):
            item = subscription.handle.take_message(subscription.msg_type, True)
            if item is None:
                break
            taken.append(item[0])
    return taken


def serialized_publish(publisher: Any) -> Callable[[bytes], None]:
    """A function publishing CDR bytes on ``publisher`` (an rclpy Publisher).

    rclpy's ``Publisher.publish(bytes)`` is ``handle.publish_raw`` behind a type check and a
    destruction guard (~3 us); the fast path calls it directly (the node outlives its loop).
    """
    return publisher.handle.publish_raw if fast_path() else publisher.publish
