"""The raw messages of one topic of a ROS 2 bag, read in bulk without importing rosbags.

rosbags' Reader yields one message per Python iteration (and importing it costs 70-250 ms of every
fresh process). This reader returns the serialized messages of one topic at once (one byte buffer,
offsets, sizes, receive times) in the order rosbags' Reader yields them:

* MCAP (:mod:`agvdyn.io._mcap`): indexed files (a summary with chunk indexes and statistics), chunks
  uncompressed or zstd / lz4 compressed;
* sqlite3 (``.db3``, the standard library's sqlite3): the query rosbags runs (``ORDER BY timestamp``);
* rosbag2 directories: metadata.yaml (version <= 9, no file or message compression, cdr topics), the
  storage files one after the other as rosbags reads them; the topics found are those of metadata.yaml.

:func:`read_topic` returns None for anything else (another storage, a compressed directory, an MCAP
file without summary, anything that does not check out): :func:`agvdyn.io.bag.read_bag` then reads the
bag with rosbags as before, which reads it or says what is wrong. ``AGVDYN_BAG_READER=rosbags`` in the
environment forces that path (tests compare both).
"""
from __future__ import annotations

import os
from pathlib import Path, PurePath


from agvdyn.io._mcap import StorageTopic, read_mcap_topic
from agvdyn.io.sidecar import _LOADER

__all__ = ["StorageTopic", "read_topic"]

#: Environment variable that forces the rosbags reader (value ``rosbags``), for tests.
READER_ENV = "AGVDYN_BAG_READER"
#: Highest rosbag2 metadata version rosbags reads.
_METADATA_VERSION = 9


def read_topic(path: Path, topic: str) -> StorageTopic | None:
    """The connections (topic, type) of a bag and the raw messages of ``topic``, in rosbags' order;
    None when this reader does not handle the bag (read it with rosbags)."""
    if os.environ.get(READER_ENV, "").lower() == "rosbags" or not path.exists():
        return None
    if path.is_dir():
        return _read_directory(path, topic)
    if path.suffix == ".mcap":
        return read_mcap_topic(path, topic)
    if path.suffix == ".db3":
        return read_sqlite_topic(path, topic)
    return None


def read_sqlite_topic(path: Path, topic: str) -> StorageTopic | None:
    """The topics of a rosbag2 sqlite3 file and the messages of ``topic`` ordered by receive time, as
    rosbags queries them; None when the file is not such a database."""
    import sqlite3  # only for sqlite3 bags

    try:
        db = sqlite3.connect(f"{path.resolve().as_uri()}?immutable=1&mode=ro", uri=True)
    except sqlite3.Error:
        return None
    try:
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {"messages", "topics"} <= tables:
            return None
        rows = db.execute("SELECT id, name, type, serialization_format FROM topics ORDER BY id").fetchall()
        ids = tuple(r[0] for r in rows if r[1] == topic)
        found = db.execute(  # rosbags' query (Sqlite3Reader.messages), so SQLite orders ties alike
            "SELECT topics.id,messages.timestamp,messages.data FROM messages JOIN topics ON messages.topic_id=topics.id "
            f"WHERE topics.id IN ({','.join('?' for _ in ids)}) ORDER BY timestamp", ids).fetchall() if ids else []
    except sqlite3.Error:
        return None
    finally:
        db.close()
    if any(not isinstance(data, bytes) for _, _, data in found):
        return None
    return StorageTopic.of_messages(tuple((r[1], r[2]) for r in rows), tuple(r[3] for r in rows if r[1] == topic),
                                    [data for _, _, data in found], [t for _, t, _ in found])


def _metadata(path: Path) -> tuple[list[Path], str, tuple[tuple[str, str], ...]] | None:
    """Storage files, storage identifier and topics (name, type) of a bag directory's metadata.yaml, when
    rosbags would read them as they are (else None)."""
    import yaml

    try:
        info = yaml.load((path / "metadata.yaml").read_text(), Loader=_LOADER)
        meta = info["rosbag2_bagfile_information"]
        if meta["version"] > _METADATA_VERSION or (meta.get("compression_mode") or "").lower() not in ("", "none"):
            return None
        meta["duration"]["nanoseconds"], meta["starting_time"]["nanoseconds_since_epoch"], meta["message_count"]
        files = [path / PurePath(f).name for f in meta["relative_file_paths"]]
        topics = [t["topic_metadata"] for t in meta["topics_with_message_count"]]
        if any(t["serialization_format"] != "cdr" for t in topics) or not all(f.is_file() for f in files):
            return None
        return files, meta["storage_identifier"], tuple((t["name"], t["type"]) for t in topics)
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return None


def _read_directory(path: Path, topic: str) -> StorageTopic | None:
    """A rosbag2 directory: its storage files one after the other (as rosbags reads them), topics from metadata.yaml."""
    meta = _metadata(path)
    if meta is None:
        return None
    files, storage, connections = meta
    reader = {"mcap": read_mcap_topic, "sqlite3": read_sqlite_topic}.get(storage)
    if reader is None:
        return None
    types = {t for name, t in connections if name == topic}
    parts = []
    for file in files:
        part = reader(file, topic)
        if part is None:
            return None
        # rosbags pairs the storage's connections with metadata.yaml's by topic and type
        if any(t not in types for name, t in part.connections if name == topic):
            return None
        parts.append(part)
    return StorageTopic.joined(connections, tuple("cdr" for name, _ in connections if name == topic), parts)
