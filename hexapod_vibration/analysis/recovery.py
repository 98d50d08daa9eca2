"""Read a rosbag2 recording that was never closed (recorder killed, machine crashed).

rosbag2 and rosbags write ``metadata.yaml`` (and the MCAP summary and footer) only when a
bag is closed. ``pph_recorder`` writes a provisional ``metadata.yaml`` when it starts
(``custom_data`` marks it open, and carries the run record) and writes its data so that
what was written survives a SIGKILL:

- MCAP: the recorder closes a chunk at least every ``CHUNK_PERIOD_S`` and flushes it to
  the file, so a killed recording is a valid MCAP prefix: a header, then complete chunks,
  then at most one partial record. :class:`_McapPrefix` reads the complete records.
- sqlite3: write-ahead log, committed in transactions of at most ``COMMIT_EVERY``
  messages, so a killed recording loses at most the last uncommitted transaction;
  :class:`_SqlitePrefix` reads what was committed (main file plus the log).

Both give the interface of rosbags' ``Reader`` that
:mod:`~hexapod_vibration.analysis.bag_files` uses (``path``, ``topics``, ``connections``,
``messages()``, ``close()``) and say in ``recovered`` what they read. No ROS import, no
third-party MCAP library (the tests check this reader against the independent ``mcap``
package).
"""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
    TopicInfo,
)

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x02, 0x03, 0x04, 0x05, 0x06
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")


def open_unfinished(path: Path, custom_data: dict[str, str], error: type[Exception]) -> Any:
    """A reader of the unfinished bag in directory ``path``.

    Raises:
        error: No data file, or one without any readable message.
    """
    files = sorted(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
    why = ("its metadata.yaml is the provisional one of a recording that was not closed"
           if custom_data else "it has no metadata.yaml")
    if len(files) != 1:
        raise error(
            f"{path} is not a readable rosbag2 bag: {why} and it holds "
            f"{len(files)} data files (not a bag, or a recording that was not closed "
            f"cleanly: `ros2 bag reindex {path}` can rebuild it)")
    reader = (_McapPrefix if files[0].suffix == ".mcap" else _SqlitePrefix)(path, files[0])
    reader.custom_data = dict(custom_data)
    if not reader.connections or reader.message_count == 0:
        reader.close()
        raise error(
            f"{path} is not a readable rosbag2 bag: {why} and {files[0].name} holds no "
            "readable message (not a bag, or a recording killed before it wrote anything)")
    reader.recovered = (f"{why}: read the {reader.message_count} messages of "
                        f"{files[0].name} {reader.extent}")
    return reader


def _connection(cid: int, topic: str, msgtype: str, owner: object) -> Connection:
    return Connection(id=cid, topic=topic, msgtype=msgtype,
                      msgdef=MessageDefinition(MessageDefinitionFormat.NONE, ""), digest="",
                      msgcount=0, ext=ConnectionExtRosbag2("cdr", []), owner=owner)


class _PrefixReader:
    """What both recovery readers share: connections, topics, message count."""

    path: Path
    connections: list[Connection]
    message_count: int
    extent: str
    custom_data: dict[str, str]
    recovered: str

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """``{topic: TopicInfo}`` like rosbags' Reader."""
        return {c.topic: TopicInfo(c.msgtype, c.msgdef, c.msgcount, [c])
                for c in self.connections}


class _McapPrefix(_PrefixReader):
    """The complete records of an MCAP file that has no summary or footer."""

    def __init__(self, path: Path, data_file: Path) -> None:
        self.path = path
        self._file = data_file.open("rb")
        size = data_file.stat().st_size
        self.connections = []
        self.message_count = 0
        self._end = 0
        if self._file.read(8) != MCAP_MAGIC:
            self.extent = "no MCAP header"
            return
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, int]] = {}
        for op, body in self._records():
            if op == _OP_SCHEMA:
                sid = _U16.unpack_from(body, 0)[0]
                schemas[sid] = _string(body, 2)[0]
            elif op == _OP_CHANNEL:
                cid, sid = struct.unpack_from("<HH", body, 0)
                channels[cid] = (_string(body, 4)[0], sid)
            elif op == _OP_MESSAGE:
                self.message_count += 1
        self.connections = [_connection(cid, topic, schemas.get(sid, ""), self)
                            for cid, (topic, sid) in sorted(channels.items())]
        self.extent = f"(complete records up to byte {self._end} of {size})"

    def _records(self) -> Iterator[tuple[int, memoryview]]:
        """(opcode, body) of every complete record, chunks opened; stops at damage.

        Reads the file sequentially, one record (at most one chunk) in memory at a time.
        """
        stream = self._file
        stream.seek(8)
        pos = 8
        while True:
            head = stream.read(9)
            if len(head) < 9:
                break
            op, length = head[0], _U64.unpack_from(head, 1)[0]
            if op == _OP_FOOTER or length > (1 << 34):
                break
            body = memoryview(stream.read(length))
            if len(body) < length:
                break
            if op == _OP_CHUNK:
                records = _chunk_records(body)
                if records is None:
                    break
                yield from _inner_records(records)
            else:
                yield op, body
            pos += 9 + length
            self._end = pos

    def messages(self, connections: Sequence[Connection] = ()) -> Iterator[
            tuple[Connection, int, memoryview]]:
        """``(connection, log time (ns), data)`` in file order."""
        wanted = {c.id: c for c in (connections or self.connections)}
        for op, body in self._records():
            if op == _OP_MESSAGE:
                conn = wanted.get(_U16.unpack_from(body, 0)[0])
                if conn is not None:
                    yield conn, _U64.unpack_from(body, 6)[0], body[22:]

    def close(self) -> None:
        """Release the file."""
        self._file.close()


def iter_mcap_messages(data_file: Path) -> Iterator[tuple[str, str, int, bytes]]:
    """``(topic, schema name, log time (ns), data)`` of every message, in file order.

    One pass, one chunk in memory at a time (rosbags' indexed reader merges every chunk at
    once, so its memory grows with the file). Stops at the first damaged record; the
    caller compares the counts with the metadata.
    """
    reader = _McapPrefix.__new__(_McapPrefix)
    reader._file = data_file.open("rb")
    reader._end = 0
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    try:
        if reader._file.read(8) != MCAP_MAGIC:
            return
        for op, body in reader._records():
            if op == _OP_MESSAGE:
                topic, schema = channels.get(_U16.unpack_from(body, 0)[0], ("", ""))
                yield topic, schema, _U64.unpack_from(body, 6)[0], bytes(body[22:])
            elif op == _OP_SCHEMA:
                schemas[_U16.unpack_from(body, 0)[0]] = _string(body, 2)[0]
            elif op == _OP_CHANNEL:
                cid, sid = struct.unpack_from("<HH", body, 0)
                channels[cid] = (_string(body, 4)[0], schemas.get(sid, ""))
            del body
    finally:
        reader.close()


def _string(body: memoryview, pos: int) -> tuple[str, int]:
    length = _U32.unpack_from(body, pos)[0]
    return bytes(body[pos + 4:pos + 4 + length]).decode("utf-8"), pos + 4 + length


def _chunk_records(body: memoryview) -> memoryview | None:
    """The records inside a chunk, decompressed; None for an unknown compression."""
    compression, pos = _string(body, 28)
    size = _U64.unpack_from(body, pos)[0]
    data = body[pos + 8:pos + 8 + size]
    if compression == "":
        return data
    try:
        if compression == "zstd":
            from backports import zstd  # rosbags' own dependency
            return memoryview(zstd.decompress(bytes(data)))
        if compression == "lz4":
            import lz4.frame
            return memoryview(lz4.frame.decompress(bytes(data)))
    except (ImportError, OSError, ValueError, RuntimeError):
        return None
    return None


def _inner_records(data: memoryview) -> Iterator[tuple[int, memoryview]]:
    pos = 0
    while pos + 9 <= len(data):
        op, length = data[pos], _U64.unpack_from(data, pos + 1)[0]
        if pos + 9 + length > len(data):
            return
        yield op, data[pos + 9:pos + 9 + length]
        pos += 9 + length


class _SqlitePrefix(_PrefixReader):
    """The committed messages of a rosbag2 sqlite3 file (its write-ahead log included)."""

    def __init__(self, path: Path, data_file: Path) -> None:
        self.path = path
        self._db = _connect(data_file)
        try:
            topics = self._db.execute("SELECT id, name, type FROM topics").fetchall()
            (self.message_count,) = self._db.execute("SELECT COUNT(*) FROM messages").fetchone()
        except sqlite3.Error:
            topics, self.message_count = [], 0
        self.connections = [_connection(int(i), str(n), str(t), self) for i, n, t in topics]
        self.extent = "(committed transactions)"

    def messages(self, connections: Sequence[Connection] = ()) -> Iterator[
            tuple[Connection, int, bytes]]:
        """``(connection, timestamp (ns), data)`` in insertion order."""
        wanted = {c.id: c for c in (connections or self.connections)}
        cursor = self._db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id")
        for cid, timestamp, data in cursor:
            conn = wanted.get(cid)
            if conn is not None:
                yield conn, int(timestamp), data

    def close(self) -> None:
        """Close the database."""
        self._db.close()


def _connect(data_file: Path) -> sqlite3.Connection:
    """Read-only connection that sees the write-ahead log if there is one."""
    try:
        db = sqlite3.connect(f"file:{data_file}?mode=ro", uri=True)
        db.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()
        return db
    except sqlite3.Error:
        return sqlite3.connect(f"file:{data_file}?immutable=1", uri=True)
