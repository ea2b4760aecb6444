"""The messages of one topic of an indexed MCAP file (https://mcap.dev/spec), read in bulk without rosbags.

An MCAP file closed by its writer (rosbag2's, rosbags') ends with a summary: the schemas, the
channels, a Chunk Index per chunk (where the chunk is, its compression, where its Message Index
records are) and the Statistics (messages per channel). The Message Index of a channel lists
(log_time, offset in the uncompressed chunk) of each of its messages: the message records are then
read with numpy, all at once per chunk (one strided view of their 31-byte record heads), with no
Python step per message. Every index entry is checked against the record it points to (opcode,
length, channel, log time) and the entries of a channel must add up to its count in the Statistics.

Order: as rosbags yields the messages (its ``McapReader.messages``): each chunk's messages sorted by
log time (stably, in record order), the chunks merged by log time, ties in the order of the chunks
in the file; messages outside their chunk's [message_start_time, message_end_time] are left out.

Anything else (no summary, no Statistics, a chunk or index that does not check out, an unknown
compression, a profile other than ros2, a channel encoding other than cdr) returns None: the caller
reads the bag with rosbags instead, which reads it or says what is wrong.
"""
from __future__ import annotations

import struct
from binascii import crc32
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["StorageTopic", "distinct", "read_mcap_topic"]

MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
_OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX, _OP_CHUNK_INDEX = 0x05, 0x06, 0x07, 0x08
_OP_STATISTICS, _OP_SUMMARY_OFFSET = 0x0B, 0x0E
#: Bytes before a message's data: opcode (1), length (8), channel (2), sequence (4), log and publish time (8 + 8).
_MESSAGE_HEAD = 31
_FOOTER_SIZE = 1 + 8 + 20 + len(MAGIC)
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_HEAD_DTYPE = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                        ("log_time", "<u8"), ("publish_time", "<u8")])


def distinct(values: np.ndarray) -> np.ndarray:
    """Sorted distinct values of a 1-d integer array (``np.unique`` without its first-call import of numpy.ma, ~10 ms)."""
    ordered = np.sort(values)
    return ordered[np.concatenate(([True], ordered[1:] != ordered[:-1]))] if ordered.size else ordered


class _Odd(Exception):
    """The file is not the plain case this reader handles: rosbags reads it."""


@dataclass(frozen=True)
class StorageTopic:
    """One storage file: its connections (topic, type) in the reader's order and the raw CDR messages of
    one topic in rosbags' order: ``data`` (uint8), message k is ``data[offsets[k]:offsets[k] + sizes[k]]``,
    received (bag receive time, int64 ns)."""

    connections: tuple[tuple[str, str], ...]
    encodings: tuple[str, ...]  # serialization format of each connection of the topic
    data: np.ndarray
    offsets: np.ndarray
    sizes: np.ndarray
    received: np.ndarray

    @classmethod
    def of_messages(cls, connections, encodings, raws: list[bytes], received) -> "StorageTopic":
        """The topic of messages given one by one (``raws``, receive times ``received``)."""
        sizes = np.fromiter(map(len, raws), dtype=np.int64, count=len(raws))
        return cls(connections, encodings, np.frombuffer(b"".join(raws), dtype=np.uint8), np.cumsum(sizes) - sizes,
                   sizes, np.asarray(received, dtype=np.int64).reshape(-1))

    @classmethod
    def joined(cls, connections, encodings, parts: list["StorageTopic"]) -> "StorageTopic":
        """The messages of ``parts`` one after the other (their bytes joined, offsets shifted)."""
        if not parts:
            empty = np.zeros(0, np.int64)
            return cls(connections, encodings, np.zeros(0, np.uint8), empty, empty, empty)
        bases = np.cumsum([0] + [p.data.size for p in parts[:-1]]).astype(np.int64)
        return cls(connections, encodings, np.concatenate([p.data for p in parts]),
                   np.concatenate([p.offsets + b for p, b in zip(parts, bases)]),
                   np.concatenate([p.sizes for p in parts]), np.concatenate([p.received for p in parts]))


@dataclass(frozen=True)
class _ChunkIndex:
    start: int
    end: int
    offset: int
    length: int
    index_offsets: dict[int, int]
    index_length: int
    compression: str
    compressed_size: int
    uncompressed_size: int


class _Cursor:
    """Little-endian fields of one record, read in order; running past the record is odd."""

    def __init__(self, buf, pos: int, end: int) -> None:
        self.buf, self.pos, self.end = buf, pos, end

    def take(self, fmt: struct.Struct) -> int:
        if self.pos + fmt.size > self.end:
            raise _Odd("record too short")
        (value,) = fmt.unpack_from(self.buf, self.pos)
        self.pos += fmt.size
        return value

    def raw(self, size: int) -> bytes:
        if self.pos + size > self.end:
            raise _Odd("record too short")
        self.pos += size
        return bytes(self.buf[self.pos - size:self.pos])

    def string(self) -> str:
        try:
            return self.raw(self.take(_U32)).decode()
        except UnicodeDecodeError as exc:
            raise _Odd("string not UTF-8") from exc


def _summary(file, size: int) -> tuple[dict, dict, list[_ChunkIndex], dict[int, int] | None]:
    """Schemas {id: name}, channels {id: (topic, schema id, encoding)}, chunk indexes and the
    Statistics' messages per channel (None without Statistics) of the summary section."""
    if size < len(MAGIC) + 9 + _FOOTER_SIZE:
        raise _Odd("too short for an MCAP file")
    start = _read_at(file, 0, min(size, 4096))
    end = _read_at(file, size - _FOOTER_SIZE, _FOOTER_SIZE)
    if start[:len(MAGIC)] != MAGIC or end[-len(MAGIC):] != MAGIC or start[len(MAGIC)] != _OP_HEADER:
        raise _Odd("no MCAP magic at both ends, or no header record")
    length = _U64.unpack_from(start, len(MAGIC) + 1)[0]
    header = _Cursor(start, len(MAGIC) + 9, min(len(start), len(MAGIC) + 9 + length))
    if header.string() != "ros2":
        raise _Odd("profile is not ros2")
    if end[0] != _OP_FOOTER or _U64.unpack_from(end, 1)[0] != 20:
        raise _Odd("no footer record")
    (summary_start,) = _U64.unpack_from(end, 9)
    footer = size - _FOOTER_SIZE
    if not len(MAGIC) + 9 + length <= summary_start <= footer:
        raise _Odd("no summary section")
    buf = _read_at(file, summary_start, footer - summary_start)
    schemas, channels, chunks, counts = {}, {}, [], None
    pos = 0
    while pos < len(buf) and buf[pos] not in (_OP_FOOTER, _OP_SUMMARY_OFFSET):
        op = buf[pos]
        rec = _Cursor(buf, pos + 9, pos + 9 + _U64.unpack_from(buf, pos + 1)[0])
        if rec.end > len(buf):
            raise _Odd("summary record past the footer")
        if op == _OP_SCHEMA:
            key = rec.take(_U16)
            schemas[key] = rec.string()
        elif op == _OP_CHANNEL:
            key = rec.take(_U16)
            schema, topic, encoding = rec.take(_U16), rec.string(), rec.string()
            channels[key] = (topic, schema, encoding)
        elif op == _OP_CHUNK_INDEX:
            chunks.append(_chunk_index(rec))
        elif op == _OP_STATISTICS:
            rec.raw(42)
            entries = np.frombuffer(rec.raw(rec.take(_U32)), dtype=[("id", "<u2"), ("count", "<u8")])
            counts = dict(zip(entries["id"].tolist(), entries["count"].tolist()))
        pos = rec.end
    if not schemas or not channels:
        raise _Odd("summary without schemas or channels")
    return schemas, channels, chunks, counts


def _read_at(file, offset: int, size: int) -> bytes:
    file.seek(offset)
    data = file.read(size)
    if len(data) != size:
        raise _Odd("file shorter than its records say")
    return data


def _chunk_index(rec: _Cursor) -> _ChunkIndex:
    start, end, offset, length = rec.take(_U64), rec.take(_U64), rec.take(_U64), rec.take(_U64)
    pairs = np.frombuffer(rec.raw(rec.take(_U32)), dtype=[("id", "<u2"), ("offset", "<u8")])
    index_length = rec.take(_U64)
    compression = rec.string()
    compressed, uncompressed = rec.take(_U64), rec.take(_U64)
    return _ChunkIndex(start, end, offset, length, dict(zip(pairs["id"].tolist(), pairs["offset"].tolist())),
                       index_length, compression, compressed, uncompressed)


def _decompress(data, compression: str, size: int) -> bytes:
    """A chunk's records, decompressed with the library rosbags uses for it (imported only when needed)."""
    if compression == "":
        return data
    if compression == "zstd":
        try:
            from compression import zstd  # Python >= 3.14
        except ImportError:
            try:
                from backports import zstd
            except ImportError as exc:
                raise _Odd("no zstd decompressor") from exc
        return zstd.decompress(bytes(data))
    if compression == "lz4":
        from lz4.frame import decompress

        return decompress(bytes(data))
    raise _Odd(f"chunk compression {compression!r}")


def _chunk_records(file, chunk: _ChunkIndex) -> np.ndarray:
    """The uncompressed records of one chunk (uint8), its size and CRC checked as rosbags does."""
    buf = _read_at(file, chunk.offset, chunk.length)
    if chunk.length < 9 + 40 or buf[0] != _OP_CHUNK or _U64.unpack_from(buf, 1)[0] != chunk.length - 9:
        raise _Odd("no chunk record at the indexed offset")
    rec = _Cursor(buf, 9, chunk.length)
    start, end, size = rec.take(_U64), rec.take(_U64), rec.take(_U64)
    crc = rec.take(_U32)
    compression, compressed = rec.string(), rec.take(_U64)
    if (start, end, size, compression, compressed) != (chunk.start, chunk.end, chunk.uncompressed_size,
                                                       chunk.compression, chunk.compressed_size):
        raise _Odd("chunk record and chunk index disagree")
    if rec.pos + compressed > rec.end:
        raise _Odd("chunk data past its record")
    raw = _decompress(memoryview(buf)[rec.pos:rec.pos + compressed], compression, size)
    if len(raw) != size or (crc and crc32(raw) != crc):
        raise _Odd("chunk size or checksum mismatch")
    return np.frombuffer(raw, dtype=np.uint8)


def _message_index(buf: bytes, offset: int, channel: int) -> np.ndarray:
    """(log_time, offset) of the messages of ``channel`` in one chunk, from its Message Index record
    at ``offset`` in ``buf`` (the chunk's Message Index records)."""
    if not 0 <= offset <= len(buf) - 15 or buf[offset] != _OP_MESSAGE_INDEX:
        raise _Odd("no message index record at the indexed offset")
    rec = _Cursor(buf, offset + 9, offset + 9 + _U64.unpack_from(buf, offset + 1)[0])
    if rec.take(_U16) != channel:
        raise _Odd("message index of another channel")
    return np.frombuffer(rec.raw(rec.take(_U32)), dtype=[("log_time", "<u8"), ("offset", "<u8")])


def _chunk_messages(file, chunk: _ChunkIndex, channels: list[int]):
    """(log_time, data offset, size) of the messages of ``channels`` in one chunk, checked against the
    records, in record order; and the chunk's records."""
    index_start = chunk.offset + chunk.length
    indexes = _read_at(file, index_start, chunk.index_length)
    lists = [_message_index(indexes, off - index_start, c) for c, off in chunk.index_offsets.items()]
    entries = np.concatenate(lists)
    channel = np.repeat(np.array(list(chunk.index_offsets), dtype=np.int64), [e.size for e in lists])
    records = _chunk_records(file, chunk)
    order = np.argsort(entries["offset"], kind="stable")
    log_time, offset = entries["log_time"][order].astype(np.int64), entries["offset"][order].astype(np.int64)
    channel = channel[order]
    if offset.size and (offset[0] < 0 or offset[-1] + _MESSAGE_HEAD > records.size or (np.diff(offset) <= 0).any()):
        raise _Odd("message index offsets outside the chunk or repeated")
    heads = sliding_window_view(records, _MESSAGE_HEAD)[offset].copy().view(_HEAD_DTYPE)[:, 0] if offset.size else \
        np.zeros(0, dtype=_HEAD_DTYPE)
    length = heads["length"].astype(np.int64)
    if ((heads["op"] != _OP_MESSAGE) | (length < 22) | (offset + 9 + length > records.size)
            | (heads["channel"] != channel) | (heads["log_time"].astype(np.int64) != log_time)).any():
        raise _Odd("a message index entry does not point to its message")
    _check_record_chain(records, offset, offset + 9 + length, channels)
    mine = np.zeros(channel.size, dtype=bool)
    for c in channels:
        mine |= channel == c
    return log_time[mine], offset[mine] + _MESSAGE_HEAD, length[mine] - 22, records


def _check_record_chain(records: np.ndarray, starts: np.ndarray, ends: np.ndarray, channels: list[int]) -> None:
    """The chunk's records follow one another from its start to its end, as rosbags walks them: the
    indexed messages (``starts``/``ends``) back to back, the records between them (schemas, channels)
    walked one by one; a message of ``channels`` that no index lists is odd."""
    expected = np.concatenate(([0], ends))
    targets = np.concatenate((starts, [records.size]))
    for k in np.flatnonzero(expected != targets).tolist():
        pos, target = int(expected[k]), int(targets[k])
        while pos < target:
            if pos + 9 > target:
                raise _Odd("records of a chunk do not chain")
            op, size = int(records[pos]), int(records[pos + 1:pos + 9].view("<u8")[0])
            if op == _OP_MESSAGE and (size < 22 or int(records[pos + 9:pos + 11].view("<u2")[0]) in channels):
                raise _Odd("a message of the topic without index entry")
            pos += 9 + size
        if pos != target:
            raise _Odd("records of a chunk do not chain")


def _compact(records: np.ndarray, offsets: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bytes of the messages at ``offsets`` packed together (grouped by size, one copy per size)
    and each message's offset in the packed bytes."""
    packed, new = [], np.empty_like(offsets)
    base = 0
    for size in distinct(sizes).tolist():
        rows = np.flatnonzero(sizes == size)
        block = sliding_window_view(records, size)[offsets[rows]] if size else np.zeros((rows.size, 0), np.uint8)
        packed.append(block.reshape(-1))
        new[rows] = base + size * np.arange(rows.size)
        base += size * rows.size
    return (np.concatenate(packed) if packed else np.zeros(0, np.uint8)), new


def _topic_channels(schemas: dict, channels: dict, topic: str) -> tuple[tuple[tuple[str, str], ...], list[int], tuple[str, ...]]:
    connections = tuple((t, schemas.get(s, "__schemaless__")) for t, s, _ in channels.values())
    ids = [cid for cid, (t, _, _) in channels.items() if t == topic]
    return connections, ids, tuple(channels[c][2] for c in ids)


def read_mcap_topic(path: Path, topic: str) -> StorageTopic | None:
    """The connections of an indexed MCAP file and the messages of ``topic``; None: read it with rosbags."""
    try:
        with open(path, "rb") as file:
            return _read(file, path.stat().st_size, topic)
    except (_Odd, OSError, ValueError, struct.error):
        return None


def _read(file, size: int, topic: str) -> StorageTopic:
    schemas, channels, chunks, counts = _summary(file, size)
    connections, ids, encodings = _topic_channels(schemas, channels, topic)
    if counts is None or not chunks:
        raise _Odd("no statistics or no chunk index")
    parts, indexed = [], 0
    for chunk in sorted(chunks, key=lambda c: c.offset):
        mine = [c for c in ids if c in chunk.index_offsets]
        if not mine:
            continue
        log_time, offsets, sizes, records = _chunk_messages(file, chunk, mine)
        indexed += log_time.size
        inside = (log_time >= chunk.start) & (log_time <= chunk.end)  # rosbags' bounds of a chunk
        data, packed = _compact(records, offsets[inside], sizes[inside])
        parts.append(StorageTopic(connections, encodings, data, packed, sizes[inside], log_time[inside]))
    if indexed != sum(counts.get(c, 0) for c in ids):
        raise _Odd("message indexes and statistics disagree on the number of messages")
    return _merged(connections, encodings, parts)


def _merged(connections, encodings, parts: list[StorageTopic]) -> StorageTopic:
    """The chunks' messages merged in rosbags' order: log time, then chunk offset, then record order."""
    whole = StorageTopic.joined(connections, encodings, parts)
    order = np.argsort(whole.received, kind="stable")  # parts in chunk order, each in record order
    return StorageTopic(connections, encodings, whole.data, whole.offsets[order], whole.sizes[order],
                        whole.received[order])
