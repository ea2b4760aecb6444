"""``sensor_msgs/msg/JointState`` messages of a bag decoded many at a time (:func:`agvdyn.io.bag.read_bag`).

rosbags decodes one message per Python call (~25 µs each: 0.9 s of a 71 s log at 500 Hz) and costs
70-250 ms to import. The messages of one publisher share their layout: the same frame id, joint
names and array lengths, so the same bytes everywhere but in the stamp and the numbers. Such
messages are decoded together: the layout is read from the first message of a group by our own
decoder of one little-endian CDR JointState (:func:`decode_joint_state`: the rules of the XCDR1
encoding, 4-byte lengths, numbers aligned to their size from the start of the payload, and the
checks rosbags makes: string terminators, sequence lengths that fit, at most 3 bytes of padding at
the end); then every message of the same length whose layout bytes equal the first's is read with
numpy views of the bytes, the first message's numbers checked bit for bit against its own decoding.
Any other message is decoded on its own, by our decoder, or, when that refuses it (big-endian,
truncated, another encapsulation), by rosbags (``deserialize``), which decodes it or raises as before.
The values are the same bits either way (tests/test_io_bag_storage.py checks against rosbags).
"""
from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from agvdyn.io._mcap import distinct

__all__ = ["JointRows", "JointStateMessage", "JointStateTable", "decode_joint_state", "decode_joint_state_table"]

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_LITTLE_ENDIAN_CDR = b"\x00\x01"
Deserialize = Callable[[bytes], Any]


class _Refused(Exception):
    """The bytes are not a little-endian CDR JointState our decoder reads as rosbags would."""


@dataclass(frozen=True)
class JointStateMessage:
    """One decoded JointState: header stamp (ns), frame id, joint names, the three float64 arrays, and
    where the arrays are in the serialized bytes ((byte offset, count) of position, velocity, effort)."""

    stamp_ns: int
    frame_id: str
    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    arrays: tuple[tuple[int, int], tuple[int, int], tuple[int, int]]


def _string(raw: bytes, pos: int, end: int) -> tuple[str, int]:
    """A CDR string at payload position ``pos``: 4-byte length with its NUL, as rosbags' check_string."""
    if pos + 4 > end:
        raise _Refused
    (length,) = _U32.unpack_from(raw, 4 + pos)
    stop = pos + 4 + length
    if length < 1 or stop > end or raw[4 + stop - 1] != 0:
        raise _Refused
    return raw[4 + pos + 4:4 + stop - 1].decode(), stop


def _count(raw: bytes, pos: int, end: int, minimum: int) -> tuple[int, int]:
    """A sequence length at payload position ``pos`` (4-aligned) and the position after it; refused
    when ``minimum`` bytes per element would not fit (rosbags' check_sequence)."""
    pos = (pos + 3) & -4
    if pos + 4 > end:
        raise _Refused
    (count,) = _U32.unpack_from(raw, 4 + pos)
    if pos + 4 + count * minimum > end:
        raise _Refused
    return count, pos + 4


def decode_joint_state(raw: bytes) -> JointStateMessage | None:
    """Our own decoder of one little-endian CDR ``sensor_msgs/msg/JointState``; None when it refuses the
    bytes (not little-endian CDR, truncated, no string terminator, more than 3 bytes left over)."""
    end = len(raw) - 4  # payload: positions count from after the 4-byte encapsulation header
    if end < 8 or raw[:2] != _LITTLE_ENDIAN_CDR:
        return None
    try:
        sec, nanosec = _STAMP.unpack_from(raw, 4)
        frame_id, pos = _string(raw, 8, end)
        count, pos = _count(raw, pos, end, 5)
        names = []
        for _ in range(count):
            name, pos = _string(raw, (pos + 3) & -4, end)
            names.append(name)
        arrays, values = [], []
        for _ in range(3):  # position, velocity, effort: sequences of float64
            count, pos = _count(raw, pos, end, 8)
            if count:
                pos = (pos + 7) & -8
            if pos + 8 * count > end:
                raise _Refused
            arrays.append((4 + pos, count))
            values.append(np.frombuffer(raw, dtype="<f8", count=count, offset=4 + pos).astype(np.float64))
            pos += 8 * count
    except (_Refused, UnicodeDecodeError):
        return None
    if pos + 3 < end:
        return None
    return JointStateMessage(sec * 1_000_000_000 + nanosec, frame_id, tuple(names), *values, tuple(arrays))


@dataclass(frozen=True)
class JointRows:
    """The messages of one joint-name layout: their indices (increasing) and position / effort per
    joint, (K, J) float64; a message whose array does not have one value per joint (JointState allows
    empty arrays) has a row of NaN."""

    rows: np.ndarray
    position: np.ndarray
    effort: np.ndarray


@dataclass(frozen=True)
class JointStateTable:
    """Decoded messages: header stamps (M,) int64 ns, and the messages of each joint-name layout."""

    stamps: np.ndarray
    layouts: dict[tuple[str, ...], JointRows]


def _values(block: np.ndarray, offset: int, count: int, width: int) -> np.ndarray:
    """(K, width) float64 read from bytes ``offset:offset + 8 count`` of each row; NaN when count != width."""
    if count != width:
        return np.full((block.shape[0], width), np.nan)
    return block[:, offset:offset + 8 * count].copy().view("<f8").astype(np.float64, copy=False)


def _layout_mask(message: JointStateMessage, size: int) -> np.ndarray:
    """Bytes that must be equal in every message of this layout (all but the stamp and the numbers)."""
    keep = np.ones(size, dtype=bool)
    keep[4:12] = False  # header.stamp: sec (int32), nanosec (uint32)
    for offset, count in message.arrays:
        keep[offset:offset + 8 * count] = False
    return keep


def _same_layout(block: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Rows of ``block`` whose bytes under ``keep`` equal the first row's, compared one run of kept bytes at a time."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], keep.view(np.int8), [0]))))
    same = np.ones(block.shape[0], dtype=bool)
    for start, stop in zip(edges[::2].tolist(), edges[1::2].tolist()):
        same &= (block[:, start:stop] == block[0, start:stop]).all(axis=1)
    return same


def _rows_of_size(data: np.ndarray, offsets: np.ndarray, size: int) -> np.ndarray:
    """(K, size) bytes of the messages at ``offsets``: a view when they lie back to back, else one copy."""
    if offsets.size and (np.diff(offsets) == size).all():
        return data[offsets[0]:offsets[0] + size * offsets.size].reshape(offsets.size, size)
    return sliding_window_view(data, size)[offsets]


class _Decoded:
    """Results gathered per layout while decoding, and messages left for one-by-one decoding."""

    def __init__(self, m: int) -> None:
        self.stamps = np.zeros(m, dtype=np.int64)
        self.parts: dict[tuple[str, ...], list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}

    def add(self, names: tuple[str, ...], rows: np.ndarray, position: np.ndarray, effort: np.ndarray) -> None:
        self.parts.setdefault(names, []).append((rows, position, effort))

    def add_one(self, k: int, stamp_ns: int, names, position, effort) -> None:
        self.stamps[k] = stamp_ns
        width = len(names)
        rows = [np.asarray(a, dtype=np.float64) if len(a) == width else np.full(width, np.nan) for a in (position, effort)]
        self.add(tuple(names), np.array([k], dtype=np.int64), rows[0][None, :], rows[1][None, :])

    def table(self) -> JointStateTable:
        layouts = {}
        for names, parts in self.parts.items():
            rows = np.concatenate([p[0] for p in parts])
            order = np.argsort(rows, kind="stable")
            layouts[names] = JointRows(rows[order], *(np.concatenate([p[i] for p in parts])[order] for i in (1, 2)))
        return JointStateTable(self.stamps, layouts)


def _decode_size_group(out: _Decoded, block: np.ndarray, rows: np.ndarray, leftover: list[int]) -> None:
    """Messages of one size (``block``: their bytes, ``rows``: their indices): up to _LAYOUTS_PER_SIZE
    layouts read with numpy; the rest appended to ``leftover``."""
    for _ in range(_LAYOUTS_PER_SIZE):  # messages of one size may still differ (frame ids, names)
        if not rows.size:
            return
        message = decode_joint_state(block[0].tobytes())
        if message is None:
            leftover.append(int(rows[0]))
            block, rows = block[1:], rows[1:]
            continue
        same = _same_layout(block, _layout_mask(message, block.shape[1]))
        done = block[same] if not same.all() else block
        width = len(message.names)
        (p_off, p_n), _, (e_off, e_n) = message.arrays
        position, effort = _values(done, p_off, p_n, width), _values(done, e_off, e_n, width)
        sec = done[:, 4:8].copy().view("<i4")[:, 0].astype(np.int64)
        nanosec = done[:, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
        stamps = sec * 1_000_000_000 + nanosec
        if stamps[0] != message.stamp_ns or (width and (  # the numpy reading of the first message = its own decoding
                (p_n == width and position[0].tobytes() != message.position.tobytes())
                or (e_n == width and effort[0].tobytes() != message.effort.tobytes()))):
            leftover.append(int(rows[0]))
            block, rows = block[1:], rows[1:]
            continue
        out.stamps[rows[same]] = stamps
        out.add(message.names, rows[same], position, effort)
        block, rows = block[~same], rows[~same]
    leftover.extend(rows.tolist())


def decode_joint_state_table(data: np.ndarray, offsets: np.ndarray, sizes: np.ndarray,
                             deserialize: Deserialize) -> JointStateTable:
    """Decode the serialized JointState messages ``data[offsets[k]:offsets[k] + sizes[k]]`` (uint8 buffer),
    grouped by layout. ``deserialize(raw)``: rosbags' decoder of one message, called only for the
    messages our own decoder refuses."""
    out = _Decoded(offsets.size)
    leftover: list[int] = []
    for size in distinct(sizes).tolist():
        rows = np.flatnonzero(sizes == size)
        _decode_size_group(out, _rows_of_size(data, offsets[rows], size), rows, leftover)
    for k in sorted(leftover):  # beyond the layouts tried: one message at a time
        raw = data[offsets[k]:offsets[k] + sizes[k]].tobytes()
        message = decode_joint_state(raw)
        if message is not None:
            out.add_one(k, message.stamp_ns, message.names, message.position, message.effort)
        else:
            ref = deserialize(raw)
            out.add_one(k, ref.header.stamp.sec * 1_000_000_000 + ref.header.stamp.nanosec, ref.name,
                        ref.position, ref.effort)
    return out.table()


#: Layouts tried per message size before the rest of that size is decoded one message at a time
#: (bounds the work when every message differs, e.g. in padding bytes).
_LAYOUTS_PER_SIZE = 8
