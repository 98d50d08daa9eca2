"""Topics of a bag as they stream by, each value placed on its loop sample.

Sample placement: a message whose ``layout.dim[1]`` is ``sample:<n>`` is placed on sample
``n`` ("in-band"). A topic whose messages carry no index (another publisher) falls back to
the bag timestamps: ``n = round((t - t0) * fs)`` with ``t0`` the earliest timestamp of the
strut topics read, so that the topics stay aligned with each other ("timestamp").
Values are sorted by sample; repeated samples keep the first message received and are
counted; gaps are counted, never interpolated.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import numpy as np

from hexapod_vibration.analysis.bag_format import STRUT_MSGTYPE, typestore
from hexapod_vibration.analysis.bag_messages import decode_array, decode_strut_message
from hexapod_vibration.contract import STRUT_COUNT, InvalidStrutMessage, parse_sample_label

IndexSource = Literal["in-band", "timestamp"]


@dataclass(frozen=True)
class StrutSeries:
    """One ``/pph/*`` topic of a bag, one row per kept sample.

    Attributes:
        topic: Topic name.
        sample_index: Loop sample index of each row, int64 (N,), strictly increasing.
        values: Values per row, float64 (N, 6) in strut order 1..6, SI units; (N, m) when
            the topic was read with a projection (:class:`Keep`).
        timestamp_ns: Bag timestamp of each row's message (ns), int64 (N,); empty when the
            topic was read without timestamps.
        missing_samples: Samples absent between the first and the last sample received.
        duplicate_samples: Messages dropped because their sample was already present.
        index_source: ``"in-band"`` (``sample:<n>`` labels) or ``"timestamp"``.
        invalid_messages: Messages skipped as unusable (undecodable bytes, wrong length,
            non-finite values, garbled or out-of-range label, or no index on a topic whose
            other messages have one).
        samples: Distinct samples received (all of them, also when rows are decimated).
        first_sample: First sample received (-1 if none).
        last_sample: Last sample received (-1 if none).
    """

    topic: str
    sample_index: np.ndarray
    values: np.ndarray
    timestamp_ns: np.ndarray
    missing_samples: int
    duplicate_samples: int
    index_source: IndexSource
    invalid_messages: int = 0
    samples: int = -1
    first_sample: int = -1
    last_sample: int = -1

    def __len__(self) -> int:
        """Number of distinct samples received (rows, unless the rows were decimated)."""
        return int(self.samples if self.samples >= 0 else self.sample_index.shape[0])

    def missing_in(self, run_samples: int) -> int:
        """Samples of the run ``[0, run_samples)`` that this topic does not have."""
        return max(int(run_samples) - len(self), 0)


@dataclass(frozen=True)
class Keep:
    """What to keep of a strut topic while streaming a bag (bounded memory).

    Attributes:
        columns: ``(6, m)`` matrix: rows keep ``values @ columns`` (m values, e.g. the
            top plate's z acceleration) instead of the six values; None keeps the six.
        every: Keep values only of samples ``n`` with ``n % every == 0`` (in-band topics;
            the sample accounting still covers every sample).
        timestamps: Keep the bag timestamps of the kept rows.
        block: If > 0, keep per block of ``block`` samples (in-band topics) the mean and
            the RMS deviation from it of each (projected) value instead of the rows:
            ``values`` is then ``(blocks, 2 m)`` (means, then RMS), ``sample_index`` the
            blocks' first samples (for plots of long runs; duplicates count twice).
    """

    columns: np.ndarray | None = None
    every: int = 1
    timestamps: bool = True
    block: int = 0

KEEP_ALL = Keep()

_BLOCK = 4096


class _SampleSet:
    """Set of sample indices as a bitmap in 64 Ki-sample chunks (1 bit per sample)."""

    CHUNK = 1 << 16

    def __init__(self) -> None:
        self._chunks: dict[int, bytearray] = {}
        self.count = 0
        self.first = -1
        self.last = -1

    def add(self, n: int) -> bool:
        """Add ``n``; True if it was there already."""
        chunk, offset = divmod(n, self.CHUNK)
        bits = self._chunks.get(chunk)
        if bits is None:
            bits = self._chunks[chunk] = bytearray(self.CHUNK // 8)
        byte, bit = divmod(offset, 8)
        if bits[byte] >> bit & 1:
            return True
        bits[byte] |= 1 << bit
        self.count += 1
        self.first = n if self.first < 0 else min(self.first, n)
        self.last = max(self.last, n)
        return False


class TopicStream:
    """Messages of one strut topic, decoded as they stream by into compact numpy blocks.

    In-band samples are accounted for in a bitmap (1 bit per sample); a row (label,
    timestamp and what :class:`Keep` keeps of the values) is stored only for the first
    copy of a sample that the Keep asks for, so a topic read for its accounting only costs
    1 bit per sample.
    """

    def __init__(self, topic: str, keep: Keep) -> None:
        """Nothing received yet on ``topic``; keep of its messages what ``keep`` says."""
        self.topic, self.keep = topic, keep
        self.invalid = 0
        self.duplicates = 0
        self._set = _SampleSet()
        self._labels: list[np.ndarray] = []   # stored rows' labels (-1: none)
        self._stamps: list[np.ndarray] = []
        self._values: list[np.ndarray] = []
        self._buf_label = np.empty(_BLOCK, np.int64)
        self._buf_stamp = np.empty(_BLOCK, np.int64)
        self._buf_values = np.empty((_BLOCK, STRUT_COUNT))
        self._n = 0
        self.first_timestamp: int | None = None
        self._blocks: dict[int, np.ndarray] = {}   # block -> [count, sums (m), squares (m)]
        width = STRUT_COUNT if keep.columns is None else int(keep.columns.shape[1])
        self._rows_wanted = keep.block > 0 or width > 0 or keep.timestamps

    def add(self, timestamp: int, data: bytes | memoryview) -> None:
        """Decode one serialized message; an unusable one is counted and skipped."""
        try:
            values, label = decode_strut_message(data)
        except InvalidStrutMessage:
            self.invalid += 1
            return
        if self.first_timestamp is None or timestamp < self.first_timestamp:
            self.first_timestamp = timestamp
        if label is not None:
            if self._set.add(label):
                self.duplicates += 1
                return
            every = max(1, self.keep.every)
            if not self._rows_wanted or (self.keep.block <= 0 and label % every):
                return
        k = self._n
        self._buf_label[k] = -1 if label is None else label
        self._buf_stamp[k] = timestamp
        self._buf_values[k] = values
        self._n += 1
        if self._n == _BLOCK:
            self._flush()

    def _flush(self) -> None:
        n = self._n
        if not n:
            return
        labels = self._buf_label[:n].copy()
        stamps = self._buf_stamp[:n].copy()
        rows = self._buf_values[:n]
        if self.keep.columns is not None:
            rows = rows @ self.keep.columns
        if self.keep.block > 0:      # in-band rows go into the blocks, only others are kept
            self._accumulate_blocks(labels, rows)
            labels, stamps = labels[labels < 0], stamps[labels < 0]
        else:
            self._values.append(np.array(rows, dtype=np.float64))
        self._labels.append(labels)
        self._stamps.append(stamps)
        self._n = 0

    def _accumulate_blocks(self, labels: np.ndarray, rows: np.ndarray) -> None:
        valid = labels >= 0
        ids, inverse = np.unique(labels[valid] // self.keep.block, return_inverse=True)
        values = rows[valid]
        width = values.shape[1]
        sums = np.zeros((ids.size, 1 + 2 * width))
        np.add.at(sums[:, 0], inverse, 1.0)
        np.add.at(sums[:, 1:1 + width], inverse, values)
        np.add.at(sums[:, 1 + width:], inverse, values ** 2)
        for k, block in enumerate(ids.tolist()):
            if block in self._blocks:
                self._blocks[block] += sums[k]
            else:
                self._blocks[block] = sums[k]

    def _block_series(self, base: StrutSeries) -> StrutSeries:
        """``base`` with its rows replaced by the per-block means and RMS deviations."""
        blocks = sorted(self._blocks)
        if not blocks:
            return base
        sums = np.stack([self._blocks[b] for b in blocks])
        width = (sums.shape[1] - 1) // 2
        count = sums[:, :1]
        mean = sums[:, 1:1 + width] / count
        rms = np.sqrt(np.maximum(sums[:, 1 + width:] / count - mean ** 2, 0.0))
        return dataclasses.replace(
            base, sample_index=np.asarray(blocks, np.int64) * self.keep.block,
            values=np.hstack([mean, rms]), timestamp_ns=np.zeros(0, np.int64))

    def series(self, t0_ns: int, sample_rate_hz: float) -> StrutSeries:
        """Place the messages on their samples: sort, drop duplicates, count gaps."""
        self._flush()
        width = STRUT_COUNT if self.keep.columns is None else int(self.keep.columns.shape[1])
        labels = np.concatenate(self._labels) if self._labels else np.zeros(0, np.int64)
        stamps = np.concatenate(self._stamps) if self._stamps else np.zeros(0, np.int64)
        values = (np.concatenate(self._values) if self._values
                  else np.zeros((labels.size if self.keep.block > 0 else 0, width)))
        if self.keep.block > 0:
            values = np.zeros((labels.size, width))   # rows went into the blocks
        self._labels, self._stamps, self._values = [], [], []
        invalid = self.invalid
        if self._set.count:
            source: IndexSource = "in-band"
            labelled = labels >= 0
            invalid += int(np.count_nonzero(~labelled))
            index, stamps, values = labels[labelled], stamps[labelled], values[labelled]
            order = np.argsort(index, kind="stable")
            index, stamps, values = index[order], stamps[order], values[order]
            distinct, duplicates = self._set.count, self.duplicates
            first, last = self._set.first, self._set.last
        else:
            source = "timestamp"
            index = _index_from_timestamps(stamps, t0_ns, sample_rate_hz)
            order = np.argsort(index, kind="stable")  # stable: the first copy comes first
            index, stamps, values = index[order], stamps[order], values[order]
            keep = np.ones(index.shape, dtype=bool)
            keep[1:] = index[1:] != index[:-1]
            duplicates = int(np.count_nonzero(~keep))
            index, stamps, values = index[keep], stamps[keep], values[keep]
            distinct = int(index.size)
            first = int(index[0]) if index.size else -1
            last = int(index[-1]) if index.size else -1
        series = StrutSeries(
            topic=self.topic,
            sample_index=index,
            values=values,
            timestamp_ns=stamps if self.keep.timestamps else np.zeros(0, np.int64),
            missing_samples=(last - first + 1 - distinct) if distinct else 0,
            duplicate_samples=duplicates,
            index_source=source,
            invalid_messages=invalid,
            samples=distinct,
            first_sample=first,
            last_sample=last,
        )
        if self.keep.block > 0:
            series = (self._block_series(series) if source == "in-band" else dataclasses.replace(
                series, sample_index=np.zeros(0, np.int64), values=np.zeros((0, 2 * width))))
        return series


def _index_from_timestamps(timestamps: np.ndarray, t0_ns: int, sample_rate_hz: float) -> np.ndarray:
    """``round((t - t0) * fs)`` on the bag timestamps (ns), as int64."""
    return np.rint((timestamps - t0_ns) * (sample_rate_hz * 1e-9)).astype(np.int64)


class VectorStream:
    """Messages of a frequency topic: values (Hz) per sample, first message per sample kept."""

    def __init__(self) -> None:
        """No message yet."""
        self.rows: dict[int, np.ndarray] = {}

    def add(self, data: bytes | memoryview) -> None:
        """Keep one serialized message's values (the first per sample).

        Raises:
            ValueError: No sample index, a non-finite value, undecodable bytes.
        """
        values, labels = decode_array(data)
        if len(labels) < 2 or not np.all(np.isfinite(values)):
            raise ValueError("no sample index, or a non-finite value")
        self.rows.setdefault(parse_sample_label(labels[1]), values)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(sample index (N,), Hz (N, K)) sorted by sample; fewer values NaN-padded to K."""
        index = np.array(sorted(self.rows), dtype=np.int64)
        width = max(v.size for v in self.rows.values())
        table = np.full((index.size, width), np.nan)
        for row, n in enumerate(index):
            values = self.rows[int(n)]
            table[row, :values.size] = values
        return index, table


class WeightsStream:
    """``/pph/notch_weights`` messages ``[tone][strut][a, b]`` (N), every n-th one kept.

    Messages whose tone count differs from the last message's (tones changed) are dropped.
    """

    def __init__(self, every: int) -> None:
        """Keep every ``every``-th message (1: all)."""
        self.every = max(1, int(every))
        self.index: list[int] = []
        self.rows: list[np.ndarray] = []
        self.tones = -1
        self._seen = 0

    def add(self, data: bytes | memoryview) -> None:
        """Count one serialized message; keep it if it is the ``every``-th one and usable."""
        self._seen += 1
        if (self._seen - 1) % self.every:
            return
        msg = typestore().deserialize_cdr(bytes(data), STRUT_MSGTYPE)
        dims = msg.layout.dim
        if len(dims) < 4:
            return
        tones = int(dims[0].size)
        if msg.data.size != tones * 12:
            return
        try:
            sample = parse_sample_label(dims[3].label)
        except InvalidStrutMessage:
            return
        if tones != self.tones:
            self.index, self.rows, self.tones = [], [], tones
        self.index.append(sample)
        self.rows.append(np.asarray(msg.data, dtype=float).reshape(tones, 6, 2))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(sample index (N,), a/b (N, T, 6, 2)) of the messages kept."""
        if not self.rows:
            return np.zeros(0, dtype=np.int64), np.zeros((0, max(self.tones, 0), 6, 2))
        return np.asarray(self.index, dtype=np.int64), np.stack(self.rows)
