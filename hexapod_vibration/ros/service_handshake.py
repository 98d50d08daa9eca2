"""A parameter client's handshake: every service answers once before a real request goes.

Fast DDS (rmw_fastrtps, Humble to Jazzy; ros2/rmw_fastrtps#842, open) can lose a service
response: the client sees the server (``wait_for_services`` is true) and sends, the server
answers, but its response writer has not matched the client's response reader yet; it
waits 100 ms, logs "failed to send response (timeout)" and drops the answer, and the client
waits for ever. A new process talking to a loaded node meets this (discovery of a new
participant takes seconds on two busy cores): ``hexapod_param`` timed out after 60 s in CI.

The cure here: a request that changes nothing (a list, a get or a describe, an empty set) is
sent again every ``RESEND_S`` until it is answered (:func:`answer_with_resends`); before a
set, which is never resent, the set service gets an empty set until it answers
(:func:`shake_hands`). An answer proves that service's response writer matched this
client's reader, and a match stays, so the requests that follow are not lost.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from rclpy.parameter_client import AsyncParameterClient
from rclpy.task import Future

RESEND_S = 1.0
"""How long (s, wall) to wait for a handshake answer before sending the request again."""

_HANDSHAKES: dict[str, Callable[[AsyncParameterClient], Future]] = {
    "list_parameters": lambda client: client.list_parameters(depth=1),
    "get_parameters": lambda client: client.get_parameters([]),
    "describe_parameters": lambda client: client.describe_parameters([]),
    "set_parameters": lambda client: client.set_parameters([]),
}


def shake_hands(client: AsyncParameterClient, spin_once: Callable[[float], None],
                timeout_s: float, resend_s: float = RESEND_S,
                services: Sequence[str] = tuple(_HANDSHAKES)) -> list[str]:
    """Send the empty requests until each service answered once, for at most ``timeout_s``.

    ``spin_once(t)`` serves the client's node for at most ``t`` seconds; ``services``:
    those to shake hands with (default: list, get, describe and set). Returns the services
    that never answered (empty when the handshake is complete).
    """
    calls = {name: (lambda name=name: _HANDSHAKES[name](client)) for name in services}
    answered = answer_with_resends(calls, spin_once, timeout_s, resend_s)
    return sorted(set(calls) - set(answered))


def answer_with_resends(calls: Mapping[str, Callable[[], Future]],
                        spin_once: Callable[[float], None], timeout_s: float,
                        resend_s: float = RESEND_S) -> dict[str, Any]:
    """Send each idempotent request, again every ``resend_s`` until answered (``timeout_s``).

    Returns the first answer of each call that was answered (a lost response costs a
    resend, not the whole timeout).
    """
    deadline = time.monotonic() + timeout_s
    sent: dict[str, list[Future]] = {name: [] for name in calls}
    answers: dict[str, Any] = {}
    last_sent_s = -resend_s
    while len(answers) < len(calls) and time.monotonic() < deadline:
        if time.monotonic() - last_sent_s >= resend_s:
            last_sent_s = time.monotonic()
            for name in calls.keys() - answers.keys():
                sent[name].append(calls[name]())
        spin_once(min(0.05, max(0.0, deadline - time.monotonic())))
        for name in calls.keys() - answers.keys():
            done = [f for f in sent[name] if f.done()]
            if done:
                answers[name] = done[0].result()
    return answers
