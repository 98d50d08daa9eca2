"""What the supervisor did that the node must tell: log lines and settings it changed."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class SupervisorEvent:
    """Something the supervisor did that the node reports.

    Attributes:
        level: ``info``, ``warn`` or ``error`` (the log level).
        message: one line for the log.
        parameter: (name, value) of a setting the supervisor changed itself (a lowered
            ``mu``), for the node to mirror into its ROS parameter; None otherwise.
    """

    level: str
    message: str
    parameter: tuple[str, Any] | None = None


class EventLog:
    """The events since the node last took them, oldest first."""

    def __init__(self) -> None:
        """Empty."""
        self._events: list[SupervisorEvent] = []

    def add(self, level: str, message: str, parameter: tuple[str, Any] | None = None) -> None:
        """Queue one event (see :class:`SupervisorEvent`)."""
        self._events.append(SupervisorEvent(level, message, parameter))

    def drain(self) -> Sequence[SupervisorEvent]:
        """The events since the last call, oldest first (and forget them).

        Called once per loop sample: with none, nothing is allocated (an empty tuple).
        """
        if not self._events:
            return ()
        events, self._events = self._events, []
        return events
