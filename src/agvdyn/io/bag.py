"""ROS 2 bags (sqlite3 and MCAP) with ``sensor_msgs/msg/JointState``, read and written without ROS.

Reading takes the raw messages of the topic in bulk from the storage files
(:mod:`agvdyn.io._bag_storage`: indexed MCAP, sqlite3, rosbag2 directories) and decodes them per
layout with numpy (:mod:`agvdyn.io._cdr`), without importing ``rosbags``; bags that reader leaves
(compressed directories, unindexed MCAP, anything odd) and messages our decoder refuses are read by
the ``rosbags`` library, as before. A ros2_control vehicle publishes its joints at slightly
irregular times, possibly in several messages per cycle (for example steering and wheel
joints from different controllers). Every mapped signal (position of angle joints, effort of
torque joints) is taken as its own time series and resampled by linear interpolation onto one
uniform time base (:data:`agvdyn.io._convert.RESAMPLING_METHOD`), over the time range common
to all signals, at ``mapping.rate`` or, by default, at the common nominal rate of the joints:
each joint's interval is estimated from that joint's own stamps (the messages that carry it) by
:func:`agvdyn.time_base.stamp_interval` (unbiased under jitter and dropped messages), the median
over the joints is rounded to 1 ns, and joints whose rates differ by more than :data:`RATE_SPREAD`
are refused unless ``rate`` is given.
Joints split over several publishers (messages interleaved, each with its own stamps) thus give
their own rate, not that of the interleaved message stream.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from agvdyn.io._bag_storage import StorageTopic, read_topic
from agvdyn.io._cdr import JointRows, decode_joint_state_table
from agvdyn.io._convert import (
    DEFAULT_GAP_PERIODS,
    RESAMPLING_METHOD,
    Series,
    check_coupling,
    converted_log,
    gap_points,
    resample,
    segments_from_ranges,
    uniform_grid,
)
from agvdyn.io.log import MAX_GAP_SAMPLES, STOP_TOLERANCE, Log, LogError
from agvdyn.io.mapping import InputKind, LogMapping, MappingError, Stamps, gear_ratio
from agvdyn.platform import Geometry
from agvdyn.time_base import fit_stamps, round_period_ns

JOINT_STATE = "sensor_msgs/msg/JointState"
#: Suffixes of single-file bag storages; a bag directory holds metadata.yaml.
BAG_SUFFIXES = (".db3", ".mcap")
Storage = Literal["sqlite3", "mcap"]
#: Largest relative spread of the joints' own rates (fastest / slowest - 1) that gives a common
#: default time base; beyond it the mapping must give ``rate``.
RATE_SPREAD = 0.10


def is_bag(path: str | os.PathLike) -> bool:
    """True for a rosbag2 directory (with metadata.yaml) or a ``.db3``/``.mcap`` file."""
    path = Path(path)
    return (path.is_dir() and (path / "metadata.yaml").exists()) or path.suffix.lower() in BAG_SUFFIXES


_JOINT_STATE_TYPES = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    JOINT_STATE: "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort",
}


def _joint_state_typestore():
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    store = get_typestore(Stores.EMPTY)
    types = {}
    for name, text in _JOINT_STATE_TYPES.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


@dataclass(frozen=True)
class _Messages:
    """JointState messages of one topic, in bag order, vectorised per joint-name layout."""

    stamps: np.ndarray  # (M,) int64 ns, header stamps
    received: np.ndarray  # (M,) int64 ns, bag receive times
    layouts: dict[tuple[str, ...], JointRows]


def _rosbags_deserializer() -> Callable[[bytes], object]:
    """rosbags' decoder of one JointState, its type store built (and rosbags imported) at the first call."""
    store = []

    def deserialize(raw: bytes):
        if not store:
            store.append(_joint_state_typestore())
        return store[0].deserialize_cdr(raw, JOINT_STATE)

    return deserialize


def _check_topic(path: Path, topic: str, connections, topic_types) -> None:
    if not topic_types:
        found = dict(connections)
        raise LogError(f"{path}: no topic {topic!r} in the bag; topics found: {found}; set 'topic' in the mapping")
    wrong = [t for t in topic_types if t != JOINT_STATE]
    if wrong:
        raise LogError(f"{path}: topic {topic!r} has message type {wrong[0]}: expected {JOINT_STATE}")


def _read_raw_rosbags(path: Path, topic: str) -> StorageTopic:
    """The raw messages of ``topic`` read by rosbags' Reader (the bags :mod:`agvdyn.io._bag_storage` leaves to it)."""
    from rosbags.rosbag2 import Reader, ReaderError

    received, raws = [], []
    try:
        with Reader(path) as reader:
            connections = tuple((c.topic, c.msgtype) for c in reader.connections)
            conns = [c for c in reader.connections if c.topic == topic]
            _check_topic(path, topic, connections, [c.msgtype for c in conns])
            for _conn, timestamp, raw in reader.messages(connections=conns):
                received.append(timestamp)
                raws.append(raw)
    except (ReaderError, FileNotFoundError) as exc:
        raise LogError(f"{path}: cannot be read as a ROS 2 bag (sqlite3 or MCAP): {exc}") from exc
    return StorageTopic.of_messages(connections, ("cdr",) * len(conns), raws, received)


def _read_messages(path: Path, topic: str) -> _Messages:
    """The JointState messages of ``topic``: read in bulk by :mod:`agvdyn.io._bag_storage` (rosbags' Reader for
    the bags it leaves), decoded per layout by :mod:`agvdyn.io._cdr` in batches of :data:`_DECODE_BATCH`."""
    raw = read_topic(path, topic)
    if raw is None:
        raw = _read_raw_rosbags(path, topic)
    else:
        _check_topic(path, topic, raw.connections, [t for name, t in raw.connections if name == topic])
    if not raw.received.size:
        raise LogError(f"{path}: topic {topic!r} has no messages")
    deserialize = _rosbags_deserializer()
    batches = [decode_joint_state_table(raw.data, raw.offsets[k:k + _DECODE_BATCH], raw.sizes[k:k + _DECODE_BATCH],
                                        deserialize) for k in range(0, raw.received.size, _DECODE_BATCH)]
    return _Messages(np.concatenate([b.stamps for b in batches]), raw.received, _joined_layouts(batches))


def _joined_layouts(batches) -> dict[tuple[str, ...], JointRows]:
    """The layouts of decoded batches (each numbering its messages from 0) as one table in bag order."""
    if len(batches) == 1:
        return batches[0].layouts
    parts: dict[tuple[str, ...], list[JointRows]] = {}
    start = 0
    for batch in batches:
        for names, rows in batch.layouts.items():
            parts.setdefault(names, []).append(JointRows(rows.rows + start, rows.position, rows.effort))
        start += batch.stamps.size
    return {names: JointRows(*(np.concatenate([getattr(r, f) for r in rs]) for f in ("rows", "position", "effort")))
            for names, rs in parts.items()}


#: Messages decoded together (:mod:`agvdyn.io._cdr`): about 30 MB of raw JointState bytes.
_DECODE_BATCH = 1 << 16


class _JointTable:
    """Values of one JointState field per joint, vectorised over the messages of each name layout."""

    def __init__(self, msgs: _Messages) -> None:
        self.layouts = msgs.layouts

    def series(self, joint: str, field: str) -> tuple[np.ndarray, np.ndarray]:
        """Message indices (bag order) and values of ``field`` of ``joint`` in the messages naming it."""
        idx, vals = [], []
        for names, rows in self.layouts.items():
            if joint in names:
                idx.append(rows.rows)
                vals.append((rows.position if field == "position" else rows.effort)[:, names.index(joint)])
        if not idx:
            return np.array([], dtype=np.int64), np.array([])
        if len(idx) == 1:
            return idx[0], vals[0]
        idx_all, vals_all = np.concatenate(idx), np.concatenate(vals)
        order = np.argsort(idx_all, kind="stable")
        return idx_all[order], vals_all[order]


def _union(stamps: list[np.ndarray]) -> np.ndarray:
    """Sorted union of strictly increasing stamp arrays (``np.unique`` of their concatenation); the
    array itself when they are all equal (a joint's position and effort from the same messages)."""
    if all(s.size == stamps[0].size and np.array_equal(s, stamps[0]) for s in stamps[1:]):
        return stamps[0]
    return np.unique(np.concatenate(stamps))


def read_bag(
    path: str | os.PathLike,
    mapping: LogMapping,
    geometry: Geometry | None = None,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
    stop_tolerance: float = STOP_TOLERANCE,
) -> Log:
    """Convert the JointState messages of a ROS 2 bag to a checked :class:`Log`.

    Parameters
    ----------
    path : bag directory (with metadata.yaml), or a single ``.db3`` / ``.mcap`` file.
    mapping : a mapping with ``input: ros2_bag`` (joints, units, topic, stamps, rate, segments, i_G).
    geometry : platform; its ``i_G`` converts motor-side angles and wheel-side torques. None: the
        mapping's ``i_G``; refused when signals need a gear ratio and neither gives it
        (:func:`agvdyn.io.mapping.gear_ratio`).
    max_gap_samples : passed to :func:`check_frame` for the converted log (default unlimited).
    stop_tolerance : steering angles beyond +-pi/2 by at most this (rad) are clipped and counted.

    Time base: ``mapping.rate``, else the common rate of the joints, each joint's interval
    estimated from its own stamps (joints split over several publishers keep their own rate);
    joints whose rates differ by more than :data:`RATE_SPREAD` are refused unless ``rate`` is
    given. Where a signal has no sample for longer than ``mapping.max_gap`` (default 5 nominal
    intervals of the slowest joint or of the time base, whichever is longer), the points of the time
    base inside that gap are left out: the log has a time gap there (a dropout, noted in
    ``sidecar['conversion']['notes']``), nothing is interpolated over it.

    Times: header stamps (``stamps: header``), or bag receive times when every header stamp
    of the topic is zero (noted in ``sidecar['conversion']['notes']``) or with ``stamps: receive``.
    The log's ``t`` starts at 0 at the first time of the uniform time base; its absolute stamp
    is ``sidecar['conversion']['t0_ns']``. Samples whose value is NaN (joint without that
    interface) are treated as missing.

    Raises
    ------
    LogError
        Missing topic, wrong message type, missing joint or field, stamps that do not increase
        for a joint, joints at different rates without ``rate``, mirror coupling violated.
    MappingError
        No gear ratio for signals that need one, or platform and mapping disagree on it.
    """
    path = Path(path)
    if mapping.input is not InputKind.ROS2_BAG:
        raise MappingError(f"{mapping.path or 'mapping'}: input is {mapping.input.value}, but {path} is a ROS 2 bag: use a mapping with input: ros2_bag")
    i_G, i_G_source = gear_ratio(mapping, geometry)
    msgs = _read_messages(path, mapping.topic)
    notes: list[str] = []
    if mapping.stamps is Stamps.RECEIVE:
        times_ns, time_kind = msgs.received, "bag receive time"
    elif not msgs.stamps.any():
        times_ns, time_kind = msgs.received, "bag receive time"
        notes.append(f"all header stamps on {mapping.topic} are zero: used the bag receive times instead")
    else:
        zero = np.flatnonzero(msgs.stamps == 0)
        if zero.size:
            k = int(zero[0])
            raise LogError(f"{path}: message #{k} on {mapping.topic} (received at {msgs.received[k]} ns) has a zero header stamp "
                           "while others have stamps: expected stamps in every message (or use stamps: receive in the mapping)")
        times_ns, time_kind = msgs.stamps, "header stamp"

    seen = sorted({n for names in msgs.layouts for n in names})
    table = _JointTable(msgs)
    raw_series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for sig in mapping.signals:
        idx, vals = table.series(sig.source, sig.field)
        ok = np.isfinite(vals)
        if not ok.any():
            present = idx.size > 0
            if present:
                raise LogError(f"{path}: joint {sig.source!r} ({sig.quantity}) never has {'an effort' if sig.field == 'effort' else 'a position'} value on {mapping.topic}: "
                               f"expected {sig.field} for {'a torque' if sig.kind == 'torque' else 'an angle'}")
            raise LogError(f"{path}: joint {sig.source!r} ({sig.quantity}) not found on {mapping.topic}; joints found: {seen}")
        t_ns = times_ns[idx]
        step = np.diff(t_ns)
        if (step <= 0).any():
            i = int(np.argmax(step <= 0))
            kind = "repeats" if step[i] == 0 else "goes back from"
            hint = " (or use the bag receive times with stamps: receive in the mapping)" if time_kind == "header stamp" else ""
            raise LogError(
                f"{path}: joint {sig.source!r}: {time_kind} of message #{idx[i + 1]} {kind} the previous one "
                f"({t_ns[i + 1]} ns after {t_ns[i]} ns): expected strictly increasing stamps per joint{hint}"
            )
        if ok.sum() < 2:
            raise LogError(f"{path}: joint {sig.source!r} ({sig.quantity}): fewer than 2 finite {sig.field} values")
        raw_series[sig.quantity] = (t_ns[ok], sig.to_si(vals[ok], i_G))

    # Each joint's interval from its own stamps (all its mapped fields), not from the message stream.
    joint_ns: dict[str, float] = {}
    counted: list[str] = []  # joints whose interval comes from counting their stamps
    fits: dict[bytes, object] = {}  # joints published in the same messages share their stamps: fitted once
    for joint in mapping.sources:
        stamps = _union([raw_series[s.quantity][0] for s in mapping.signals if s.source == joint])
        if stamps.size > 1 and stamps.tobytes() not in fits:
            fits[stamps.tobytes()] = fit_stamps(stamps, source=f"{path}: joint {joint!r}")
        fit = fits[stamps.tobytes()] if stamps.size > 1 else None
        joint_ns[joint] = fit.interval if fit is not None else float("nan")
        if fit is not None and not fit.lattice and mapping.rate is None:
            counted.append(joint)
    if counted:
        notes.append(f"stamps of {', '.join(map(repr, counted))}: too few or too jittered to show their lattice: interval by "
                     "counting the stamps, which single dropped messages would lengthen; set 'rate' in the mapping if it is known")
    intervals = np.array([v for v in joint_ns.values() if np.isfinite(v) and v > 0])
    if intervals.size == 0:
        raise LogError(f"{path}: cannot infer a sample rate from the stamps; set 'rate' in the mapping")
    source_ns = float(np.median(intervals))
    slowest_ns = float(intervals.max())
    if mapping.rate is not None:
        period_ns = int(round(1e9 / mapping.rate))
    else:
        if slowest_ns > (1.0 + RATE_SPREAD) * float(intervals.min()):
            rates = ", ".join(f"{j!r} {1e9 / v:.4g} Hz" for j, v in joint_ns.items() if np.isfinite(v))
            raise LogError(
                f"{path}: the joints on {mapping.topic} publish at different rates ({rates}; each from its own stamps), "
                f"more than {RATE_SPREAD:.0%} apart: there is no common time base; choose one with a top-level line "
                f"'rate: <Hz>' in the mapping (for example rate: {1e9 / max(round(float(intervals.min())), 1):.6g}, "
                "the fastest joint's)"
            )
        period_ns = round_period_ns(source_ns)
        if period_ns <= 0:
            raise LogError(f"{path}: cannot infer a sample rate from the stamps; set 'rate' in the mapping")
    t0_ns = max(int(t[0]) for t, _ in raw_series.values())
    series = {}
    for sig in mapping.signals:
        t_ns, v = raw_series[sig.quantity]
        series[sig.quantity] = Series(f"joint {sig.source!r} {sig.field} ({sig.quantity})", (t_ns - t0_ns) / 1e9, v)
    period = period_ns / 1e9
    # Default: 5 nominal intervals of the slowest joint or of the time base, whichever is longer.
    max_gap = mapping.max_gap if mapping.max_gap is not None else DEFAULT_GAP_PERIODS * max(period, slowest_ns / 1e9)
    grid = uniform_grid(series, period)
    keep, gap_notes = gap_points(series, grid, max_gap, f" (log time; 0 = {time_kind} {t0_ns} ns)")
    notes.extend(gap_notes)
    t = grid[keep]
    signals = {k: v[keep] for k, v in resample(series, grid).items()}
    segments = segments_from_ranges(t, mapping.segments) if isinstance(mapping.segments, tuple) else None
    coupling = check_coupling(signals, t, mapping, str(path))
    conversion = {
        "input": "ros2_bag", "file": str(path), "mapping": str(mapping.path) if mapping.path else None,
        "topic": mapping.topic, "time": time_kind, "t0_ns": t0_ns, "rate": 1e9 / period_ns,
        "joint_rates": {j: (1e9 / v if np.isfinite(v) else None) for j, v in joint_ns.items()},
        "method": RESAMPLING_METHOD, "max_gap": max_gap, "messages": int(len(msgs.stamps)),
        "i_G": i_G, "i_G_source": i_G_source, "notes": notes,
    }
    if coupling:
        conversion["coupling_max_deviation"] = coupling
    return converted_log(path, mapping, t, signals, segments, conversion, max_gap_samples=max_gap_samples,
                         stop_tolerance=stop_tolerance)
