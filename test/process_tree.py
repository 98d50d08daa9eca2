"""Processes by pid, from /proc: alive or not, whose children, gone within a hang guard."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

HANG_GUARD_S = 90.0


def alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def children_of(pid: int) -> list[int]:
    """Pids whose parent is ``pid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def command_of(pid: int) -> str:
    """The command line of ``pid`` (for messages)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:200]
    except OSError:
        return f"pid {pid} (gone)"


def wait_gone(pids: list[int]) -> list[int]:
    """Pids still alive after the hang guard (those are SIGKILLed, so none leaks).

    A pid that leads its process group is killed with its group.
    """
    deadline = time.monotonic() + HANG_GUARD_S
    while time.monotonic() < deadline and any(alive(p) for p in pids):
        time.sleep(0.1)
    left = [p for p in pids if alive(p)]
    for pid in left:
        try:
            os.killpg(pid, signal.SIGKILL)
        except OSError:                    # not a group leader
            os.kill(pid, signal.SIGKILL)
    return left
