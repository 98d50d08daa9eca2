"""Outputs that are complete or absent: written under a temporary name, then renamed.

An interrupted tool (Ctrl-C, SIGTERM, a crash) never leaves a half-written file or folder
behind: :func:`write_text` writes ``.<name>.partial-*`` next to the file and renames it
(``os.replace``: atomic on POSIX); :func:`staged` gives a tool a temporary folder next to
its output folder and moves the finished files into place only when the tool is done
(the whole folder in one rename when it did not exist yet). The moves run with the stop
signals deferred (``cli.deferred``), so an interruption lands before or after them.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from hexapod_vibration import cli


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (a reader sees the old file or the new one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, partial = tempfile.mkstemp(prefix=f".{path.name}.partial-", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.chmod(partial, 0o666 & ~_umask())
        os.replace(partial, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(partial)
        raise
    return path


@contextlib.contextmanager
def staged(out: Path) -> Iterator[Path]:
    """A temporary folder to write ``out``'s files into; published when the block succeeds.

    On an exception (an interruption included) the temporary folder is removed and ``out``
    is left as it was.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging: Path | None = None
    try:
        with cli.deferred():     # a signal now is raised once the folder is known
            staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
        yield staging
    except BaseException:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
        raise
    with cli.deferred():
        _publish(staging, out)


def _publish(staging: Path, out: Path) -> None:
    """Move the finished files of ``staging`` into ``out`` and remove ``staging``."""
    os.chmod(staging, 0o777 & ~_umask())
    if not out.exists():
        os.replace(staging, out)
        return
    for folder, _, files in os.walk(staging):
        target = out / Path(folder).relative_to(staging)
        target.mkdir(parents=True, exist_ok=True)
        for name in files:
            os.replace(Path(folder) / name, target / name)
    shutil.rmtree(staging, ignore_errors=True)
