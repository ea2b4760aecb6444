"""Writing a log as a ROS 2 bag of JointState messages (the inverse of :func:`agvdyn.io.bag.read_bag`,
for tests, benchmarks and users who want to feed a bag pipeline): sqlite3 or MCAP, joints split over
publishers with their own stamp offsets if asked."""
from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from agvdyn.io.bag import JOINT_STATE, Storage
from agvdyn.io.log import Log, LogError
from agvdyn.io.mapping import HEADING_QUANTITIES, InputKind, LogMapping, MappingError, gear_ratio
from agvdyn.platform import Geometry, read_platform

__all__ = ["write_bag"]


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


#: The message definitions a JointState needs, as in ROS 2 Humble's type store (equal field
#: definitions; tested): reading builds a store of these three instead of all of ROS 2's types
#: (75-140 ms of every bag read).
def write_bag(
    log: Log,
    path: str | os.PathLike,
    mapping: LogMapping | str | os.PathLike,
    storage: Storage = "sqlite3",
    *,
    platform: Geometry | str | os.PathLike | None = None,
    start_ns: int = 1_700_000_000_000_000_000,
    groups: Sequence[Sequence[str]] | None = None,
    group_offsets_ns: Sequence[int] | None = None,
) -> Path:
    """Write a log as a ROS 2 bag of JointState messages named as in ``mapping``.

    One message per sample on ``mapping.topic`` with header stamp and receive time
    ``start_ns + round(t * 1e9)``; every joint of the mapping in each message, ``position``
    and ``effort`` in the mapping's raw units (inverse of :meth:`Signal.to_si`), NaN where a joint
    has no such interface (as ros2_control's joint_state_broadcaster does), ``velocity`` empty.
    Mapped rear headings are written as the mirror coupling gives them (-alpha). The bag
    directory is written beside ``path`` and renamed into place; an existing ``path`` is refused.

    With ``groups`` the joints are split over several publishers, as separate controllers do:
    per sample one message per group holding only that group's joints, stamped
    ``start_ns + round(t * 1e9) + group_offsets_ns[g]`` (default offset 0; the values stay those
    of time t, so an offset shifts that group in time), messages interleaved in stamp order.

    Parameters
    ----------
    log : the log to write.
    path : bag directory to create.
    mapping : a :class:`LogMapping` with ``input: ros2_bag``, or the path of a mapping file.
    storage : ``"sqlite3"`` or ``"mcap"``.
    platform : Geometry or platform file whose ``i_G`` converts gear sides; None: the platform
        recorded in the log's sidecar, else the mapping's ``i_G``; refused when signals need a
        gear ratio and none of these gives it, or when platform and mapping disagree.
    start_ns : absolute stamp of ``t = 0``.
    groups : joint names per publisher; every joint of the mapping in exactly one group. None: one
        message with all joints per sample.
    group_offsets_ns : stamp offset of each group, ns (default all 0).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    from agvdyn.io.log import sidecar_platform
    from agvdyn.io.mapping_file import read_mapping

    path = Path(path)
    if not isinstance(mapping, LogMapping):
        mapping = read_mapping(mapping)
    if isinstance(platform, Geometry):
        geometry = platform
    elif platform is not None:
        geometry = read_platform(platform)
    else:
        geometry = sidecar_platform(log)
    i_G, _ = gear_ratio(mapping, geometry)
    if mapping.input is not InputKind.ROS2_BAG:
        raise MappingError(f"{mapping.path or 'mapping'}: input is {mapping.input.value}: writing a bag needs input: ros2_bag")
    plugins = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
    if storage not in plugins:
        raise ValueError(f"storage={storage!r}: expected one of {list(plugins)}")
    if path.exists():
        raise LogError(f"{path} exists already: not overwriting a bag")
    joints = list(mapping.sources)
    if groups is None:
        groups = [joints]
    groups = [list(g) for g in groups]
    flat = [j for g in groups for j in g]
    if sorted(flat) != sorted(joints) or len(set(flat)) != len(flat):
        raise ValueError(f"groups={groups!r}: expected every joint of the mapping {joints} in exactly one group")
    offsets = [0] * len(groups) if group_offsets_ns is None else [int(o) for o in group_offsets_ns]
    if len(offsets) != len(groups):
        raise ValueError(f"group_offsets_ns: {len(offsets)} offsets for {len(groups)} groups")
    values = {c: log.frame[c].to_numpy(dtype=np.float64) for c in log.frame.columns if c != "segment"}
    for heading, alpha in HEADING_QUANTITIES.items():
        values[heading] = -values[alpha]
    n = log.n_samples
    position = np.full((n, len(joints)), np.nan)
    effort = np.full((n, len(joints)), np.nan)
    for sig in mapping.signals:
        target = effort if sig.field == "effort" else position
        target[:, joints.index(sig.source)] = sig.from_si(values[sig.quantity], i_G)
    stamps = start_ns + np.round(log.t * 1e9).astype(np.int64)

    typestore = _typestore()
    JointState = typestore.types[JOINT_STATE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    empty = np.array([], dtype=np.float64)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_parent = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    tmp = tmp_parent / path.name
    try:
        with Writer(tmp, version=9, storage_plugin=plugins[storage]) as writer:
            conn = writer.add_connection(mapping.topic, JOINT_STATE, typestore=typestore)
            cols = [np.array([joints.index(j) for j in g], dtype=np.int64) for g in groups]
            # (stamp, group, sample) in stamp order: publishers interleave in the bag.
            g_all = np.repeat(np.arange(len(groups)), n)
            k_all = np.tile(np.arange(n), len(groups))
            ns_all = np.concatenate([stamps + off for off in offsets])
            order = np.lexsort((g_all, ns_all))
            for ns, g, k in zip(ns_all[order].tolist(), g_all[order].tolist(), k_all[order].tolist()):
                # one message per sample and group: the bag format is per message
                msg = JointState(
                    header=Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=""),
                    name=groups[g], position=position[k, cols[g]], velocity=empty, effort=effort[k, cols[g]],
                )
                writer.write(conn, ns, typestore.serialize_cdr(msg, JOINT_STATE))
        os.replace(tmp, path)
    finally:
        shutil.rmtree(tmp_parent, ignore_errors=True)
    return path
