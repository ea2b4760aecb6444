"""The bulk reader of bag storage files (agvdyn.io._bag_storage, _mcap) and the JointState decoder
(agvdyn.io._cdr) against rosbags, on bags written by rosbags' Writer: the same raw messages in the
same order with the same receive times, the same decoded bits, and load_log's Log identical whichever
reader ran (AGVDYN_BAG_READER=rosbags forces rosbags' Reader)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from agvdyn.io import LogError, load_log
from agvdyn.io._bag_storage import READER_ENV, read_topic
from agvdyn.io._cdr import decode_joint_state, decode_joint_state_table
from agvdyn.io.bag import JOINT_STATE
from agvdyn.platform import PROTOTYPE

TS = get_typestore(Stores.ROS2_HUMBLE)
JS, HEADER, TIME = (TS.types[n] for n in (JOINT_STATE, "std_msgs/msg/Header", "builtin_interfaces/msg/Time"))
TWIST, VEC = TS.types["geometry_msgs/msg/Twist"], TS.types["geometry_msgs/msg/Vector3"]
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "mappings" / "ros2_control.yaml"
PLUGINS = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
START_NS = 1_731_000_000_000_000_000


def joint_state(stamp_ns: int, names, position, effort, frame_id="base_link", velocity=()) -> bytes:
    msg = JS(header=HEADER(stamp=TIME(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame_id),
             name=list(names), position=np.asarray(position, dtype=float), velocity=np.asarray(velocity, dtype=float),
             effort=np.asarray(effort, dtype=float))
    return bytes(TS.serialize_cdr(msg, JOINT_STATE))


def twist() -> bytes:
    zero = VEC(x=0.0, y=0.0, z=0.0)
    return bytes(TS.serialize_cdr(TWIST(linear=VEC(x=1.0, y=0.0, z=0.0), angular=zero), "geometry_msgs/msg/Twist"))


def write(path: Path, storage: str, events, compression: CompressionMode = CompressionMode.NONE) -> Path:
    """A bag of ``events`` (topic, receive ns, raw bytes), in that order; topics /joint_states (two
    connections when an event names /joint_states#2), /cmd_vel and /empty (no messages)."""
    writer = Writer(path, version=9, storage_plugin=PLUGINS[storage])
    if compression is not CompressionMode.NONE:
        writer.set_compression(compression, CompressionFormat.ZSTD)
    qos = Qos(QosHistory.KEEP_LAST, 10, QosReliability.BEST_EFFORT, QosDurability.VOLATILE, QosTime(0, 0),
              QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)
    with writer:
        conns = {"/joint_states": writer.add_connection("/joint_states", JOINT_STATE, typestore=TS),
                 "/cmd_vel": writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=TS)}
        writer.add_connection("/empty", JOINT_STATE, typestore=TS)
        if any(topic == "/joint_states#2" for topic, _, _ in events):
            conns["/joint_states#2"] = writer.add_connection("/joint_states", JOINT_STATE, typestore=TS,
                                                             offered_qos_profiles=[qos])
        for topic, ns, raw in events:
            writer.write(conns[topic], ns, raw)
    return path


def by_rosbags(path: Path, topic: str) -> list[tuple[int, bytes]]:
    with Reader(path) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, bytes(raw)) for _, t, raw in reader.messages(connections=conns)] if conns else []


def by_us(path: Path, topic: str) -> list[tuple[int, bytes]]:
    got = read_topic(path, topic)
    assert got is not None, f"{path}: the bulk reader left the bag to rosbags"
    assert got.offsets.shape == got.sizes.shape == got.received.shape and got.received.dtype == np.int64
    return [(int(t), got.data[o:o + s].tobytes()) for t, o, s in zip(got.received, got.offsets, got.sizes)]


def storage_file(path: Path, storage: str) -> Path:
    return next(path.glob("*.mcap" if storage == "mcap" else "*.db3"))


def events_of(rng, n: int, *, ties: bool = True, second_connection: bool = False, frame_id: str = "base") -> list:
    """JointState events at receive times in random order (many ties: whole milliseconds), cmd_vel in between."""
    stamps = START_NS + (rng.integers(0, max(n // 3, 1), n) * 1_000_000 if ties else rng.integers(0, n * 2_000_000, n))
    events = []
    for k, ns in enumerate(stamps.tolist()):
        names = ["a", "bb", "ccc"][:1 + k % 3] if k % 7 == 3 else ["a", "bb"]
        topic = "/joint_states#2" if second_connection and k % 5 == 0 else "/joint_states"
        events.append((topic, ns, joint_state(ns, names, rng.normal(size=len(names)), rng.normal(size=len(names)),
                                              frame_id=frame_id)))
        if k % 4 == 0:
            events.append(("/cmd_vel", ns + 1, twist()))
    return events


def chunk_count(file: Path) -> int:
    from rosbags.rosbag2.storage_mcap import McapReader

    reader = McapReader(file)
    reader.open()
    try:
        return len(reader.chunks)
    finally:
        reader.close()


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_the_raw_messages_are_rosbags_in_rosbags_order(tmp_path, storage):
    """Several chunks with overlapping, unsorted receive times and ties, two connections on the topic,
    another topic in between: the same (receive time, bytes) sequence, from the directory and the file."""
    events = events_of(np.random.default_rng(1), 6000, second_connection=True, frame_id="base_link" * 30)
    bag = write(tmp_path / "bag", storage, events)
    if storage == "mcap":
        assert chunk_count(storage_file(bag, storage)) >= 3
    for path in (bag, storage_file(bag, storage)):
        for topic in ("/joint_states", "/cmd_vel", "/empty"):
            assert by_us(path, topic) == by_rosbags(path, topic), (path, topic)
    got = read_topic(bag, "/joint_states")
    with Reader(bag) as reader:
        assert got.connections == tuple((c.topic, c.msgtype) for c in reader.connections)


def test_zstd_compressed_chunks_are_read_and_compressed_files_left_to_rosbags(tmp_path):
    events = events_of(np.random.default_rng(2), 4000, frame_id="base_link" * 30)
    chunked = write(tmp_path / "chunks", "mcap", events, CompressionMode.STORAGE)
    assert chunk_count(storage_file(chunked, "mcap")) >= 2
    assert by_us(chunked, "/joint_states") == by_rosbags(chunked, "/joint_states")
    for mode in (CompressionMode.FILE, CompressionMode.MESSAGE):
        bag = write(tmp_path / mode.name, "mcap", events[:50], mode)
        assert read_topic(bag, "/joint_states") is None  # rosbags reads these
        assert by_rosbags(bag, "/joint_states")


def test_a_truncated_or_damaged_file_is_a_log_error_naming_it(tmp_path):
    bag = write(tmp_path / "bag", "mcap", events_of(np.random.default_rng(3), 300))
    file = storage_file(bag, "mcap")
    data = file.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    assert read_topic(cut, "/joint_states") is None
    with pytest.raises(LogError, match=r"cut\.mcap: cannot be read as a ROS 2 bag"):
        load_log(cut, EXAMPLE, PROTOTYPE)
    for at in np.linspace(0, len(data) - 1, 41).astype(int).tolist():  # one damaged byte anywhere
        flipped = bytearray(data)
        flipped[at] ^= 0xFF
        bad = tmp_path / "bad.mcap"
        bad.write_bytes(bytes(flipped))
        ours = read_topic(bad, "/joint_states")
        if ours is not None:  # read only what rosbags reads, and then the same
            assert by_us(bad, "/joint_states") == by_rosbags(bad, "/joint_states"), at
    junk = tmp_path / "junk.db3"
    junk.write_bytes(b"not a database" * 100)
    assert read_topic(junk, "/joint_states") is None
    with pytest.raises(LogError, match=r"junk\.db3: cannot be read as a ROS 2 bag"):
        load_log(junk, EXAMPLE, PROTOTYPE)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_an_empty_topic_and_a_missing_topic_say_so(tmp_path, storage, monkeypatch):
    bag = write(tmp_path / "bag", storage, events_of(np.random.default_rng(4), 50))
    for topic, message in (("/empty", "has no messages"), ("/nothing", "no topic '/nothing' in the bag; topics found"),
                           ("/cmd_vel", "has message type geometry_msgs/msg/Twist")):
        mapping = EXAMPLE.read_text().replace("topic: /joint_states", f"topic: {topic}")
        (tmp_path / "m.yaml").write_text(mapping)
        errors = []
        for reader in ("", "rosbags"):
            monkeypatch.setenv(READER_ENV, reader)
            with pytest.raises(LogError, match=message) as info:
                load_log(bag, tmp_path / "m.yaml", PROTOTYPE)
            errors.append(str(info.value))
        assert errors[0] == errors[1]


def rosbags_decoded(raw: bytes):
    return TS.deserialize_cdr(raw, JOINT_STATE)


def assert_table_is_rosbags(raws: list[bytes]) -> None:
    sizes = np.array([len(r) for r in raws], dtype=np.int64)
    offsets = np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.int64)
    table = decode_joint_state_table(np.frombuffer(b"".join(raws), dtype=np.uint8), offsets, sizes, rosbags_decoded)
    seen = np.zeros(len(raws), dtype=int)
    for names, rows in table.layouts.items():
        assert (np.diff(rows.rows) > 0).all() and rows.position.shape == rows.effort.shape == (rows.rows.size, len(names))
        for k, p, e in zip(rows.rows, rows.position, rows.effort):
            ref = rosbags_decoded(raws[k])
            seen[k] += 1
            assert tuple(ref.name) == names
            assert table.stamps[k] == ref.header.stamp.sec * 1_000_000_000 + ref.header.stamp.nanosec
            for got, want in ((p, ref.position), (e, ref.effort)):
                want = np.asarray(want, dtype=np.float64) if len(want) == len(names) else np.full(len(names), np.nan)
                assert got.tobytes() == want.tobytes()
    assert (seen == 1).all()


def test_a_publisher_mix_is_decoded_per_layout_without_rosbags():
    """400 messages of five layouts (frame ids, names, array lengths, NaN efforts) as rosbags reads them,
    rosbags' own decoder never called for little-endian messages."""
    rng = np.random.default_rng(3)
    layouts = [(["a", "bb"], 2, 2, "base"), (["steer_l", "steer_r", "w"], 3, 0, "base_link"),
               (["a", "bb"], 2, 2, "odom"), (["x"], 1, 1, ""), (["a", "bb", "ccc"], 3, 3, "base")]
    raws = []
    for _ in range(400):
        names, n_pos, n_eff, frame = layouts[int(rng.integers(len(layouts)))]
        eff = rng.normal(size=n_eff)
        eff[rng.random(n_eff) < 0.3] = np.nan
        msg = JS(header=HEADER(stamp=TIME(sec=int(rng.integers(0, 2**31)), nanosec=int(rng.integers(0, 10**9))),
                               frame_id=frame),
                 name=names, position=rng.normal(size=n_pos), velocity=rng.normal(size=int(rng.integers(0, 2))),
                 effort=eff)
        raws.append(bytes(TS.serialize_cdr(msg, JOINT_STATE)))
    calls = []
    sizes = np.array([len(r) for r in raws], dtype=np.int64)
    offsets = np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.int64)
    decode_joint_state_table(np.frombuffer(b"".join(raws), dtype=np.uint8), offsets, sizes, calls.append)
    assert calls == []
    assert_table_is_rosbags(raws)


_float = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def messages(draw):
    """Serialized JointStates of a few layouts (empty arrays, odd-length names and frame ids included),
    a few big-endian ones among them."""
    layouts = draw(st.lists(st.tuples(st.lists(st.text("abcxyz_/é", min_size=0, max_size=7), max_size=4),
                                      st.text("base_link", max_size=6), st.booleans()), min_size=1, max_size=3))
    out = []
    for _ in range(draw(st.integers(1, 40))):
        names, frame, with_effort = draw(st.sampled_from(layouts))
        stamp = draw(st.integers(0, 2**31 - 1)) * 10**9 + draw(st.integers(0, 10**9 - 1))
        pos = draw(st.lists(_float, min_size=len(names), max_size=len(names)))
        eff = draw(st.lists(_float, min_size=len(names), max_size=len(names))) if with_effort else []
        vel = draw(st.lists(_float, max_size=2))
        msg = JS(header=HEADER(stamp=TIME(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id=frame), name=names,
                 position=np.array(pos, dtype=float), velocity=np.array(vel, dtype=float), effort=np.array(eff, dtype=float))
        out.append(bytes(TS.serialize_cdr(msg, JOINT_STATE, little_endian=draw(st.integers(0, 9)) > 0)))
    return out


@settings(max_examples=60, deadline=None)
@given(messages())
def test_decoded_stamps_and_values_are_rosbags_bits(raws):
    assert_table_is_rosbags(raws)
    for raw in raws:
        own = decode_joint_state(raw)
        if raw[1] == 0:  # big-endian: left to rosbags
            assert own is None
            continue
        ref = rosbags_decoded(raw)
        assert own.names == tuple(ref.name) and own.frame_id == ref.header.frame_id
        assert own.stamp_ns == ref.header.stamp.sec * 1_000_000_000 + ref.header.stamp.nanosec
        for got, want in zip((own.position, own.velocity, own.effort), (ref.position, ref.velocity, ref.effort)):
            assert got.dtype == np.float64 and got.tobytes() == np.asarray(want, dtype=np.float64).tobytes()


@settings(max_examples=40, deadline=None)
@given(raw=messages().map(lambda r: r[0]), cut=st.integers(1, 400))
def test_our_decoder_refuses_what_rosbags_refuses(raw, cut):
    """A truncated message: our decoder reads it only when rosbags does, and then to the same values."""
    short = raw[:max(len(raw) - cut, 0)]
    try:
        ref = rosbags_decoded(short)
    except Exception:
        assert decode_joint_state(short) is None
        return
    own = decode_joint_state(short)
    if own is not None:
        assert own.names == tuple(ref.name) and own.position.tobytes() == np.asarray(ref.position, float).tobytes()


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), storage=st.sampled_from(["mcap", "sqlite3"]),
       compressed=st.booleans())
def test_any_small_bag_reads_as_rosbags_reads_it(tmp_path_factory, seed, n, storage, compressed):
    mode = CompressionMode.STORAGE if compressed and storage == "mcap" else CompressionMode.NONE
    bag = write(tmp_path_factory.mktemp("bag") / "bag", storage, events_of(np.random.default_rng(seed), n), mode)
    assert by_us(bag, "/joint_states") == by_rosbags(bag, "/joint_states")


def write_vehicle_bag(path: Path, storage: str, *, big_endian_at: int | None = None) -> Path:
    """All eight joints of the example mapping per message at 500 Hz, jittered stamps, 2 s; a frame id
    change (another layout) in the middle."""
    rng = np.random.default_rng(5)
    names = [j for pair in (("front_left_steering_joint", "rear_left_steering_joint"),
                            ("front_right_steering_joint", "rear_right_steering_joint"),
                            ("front_left_wheel_joint", "rear_left_wheel_joint"),
                            ("front_right_wheel_joint", "rear_right_wheel_joint")) for j in pair]
    events = []
    for k in range(1000):
        ns = START_NS + k * 2_000_000 + int(rng.integers(-300_000, 300_000))
        s = k * 0.002
        a_l, a_r = 0.3 * np.sin(s), 0.2 * np.sin(1.3 * s)
        pos = [a_l, -a_l, a_r, -a_r, 4 * s, 4.1 * s, 3.9 * s, 4 * s]
        eff = [np.nan] * 4 + list(5 + rng.normal(size=4))
        msg = JS(header=HEADER(stamp=TIME(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="odom" if k == 500 else "base"),
                 name=names, position=np.array(pos), velocity=np.array([]), effort=np.array(eff))
        events.append(("/joint_states", ns + 100_000, bytes(TS.serialize_cdr(msg, JOINT_STATE, little_endian=k != big_endian_at))))
    return write(path, storage, events)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_load_log_is_the_same_log_whichever_reader(tmp_path, storage, monkeypatch):
    """A frame id change (another layout) and a big-endian message in the middle; every column and
    the sidecar equal to those of rosbags' Reader."""
    bag = write_vehicle_bag(tmp_path / "bag", storage, big_endian_at=700)
    logs = []
    for reader in ("", "rosbags"):
        monkeypatch.setenv(READER_ENV, reader)
        logs.append(load_log(bag, EXAMPLE, PROTOTYPE))
    fast, slow = logs
    assert list(fast.frame.columns) == list(slow.frame.columns)
    for column in fast.frame.columns:
        a, b = fast.frame[column].to_numpy(), slow.frame[column].to_numpy()
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    assert fast.sidecar == slow.sidecar
    assert fast.sidecar["conversion"]["messages"] == 1000


def test_lz4_and_zstd_chunks_decompress_to_their_records():
    """The decompressors of MCAP chunks (rosbags' Writer writes only zstd ones; lz4 checked on its own)."""
    import lz4.frame

    from agvdyn.io._mcap import _decompress

    records = b"".join(joint_state(START_NS + k, ["a", "bb"], [k, -k], [0.5, np.nan]) for k in range(200))
    assert _decompress(lz4.frame.compress(records), "lz4", len(records)) == records
    assert bytes(_decompress(memoryview(records), "", len(records))) == records
