"""One entry point for every command that takes a log: :func:`load_log`."""
from __future__ import annotations

import os
from pathlib import Path

from agvdyn.io.bag import is_bag, read_bag
from agvdyn.io.log import LOG_SUFFIXES, MAX_GAP_SAMPLES, Log, LogError, read_log
from agvdyn.io.mapping import InputKind, LogMapping, read_mapping
from agvdyn.io.table import read_mapped_table
from agvdyn.platform import PROTOTYPE, Geometry, read_platform

PathLike = str | os.PathLike


def load_log(
    path: PathLike,
    mapping: LogMapping | PathLike | None = None,
    platform: Geometry | PathLike | None = None,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
) -> Log:
    """Load any supported log as a checked :class:`Log` in our schema (PLATFORM.md "Files").

    This signature is stable: every command that takes a log calls it.

    Parameters
    ----------
    path : one of
        - ``*.parquet`` / ``*.csv`` in our schema (no mapping needed; sidecar ``<path>.yaml`` read),
        - ``*.csv`` / ``*.parquet`` with other column names or units, with a mapping ``input: table``,
        - a ROS 2 bag (directory with metadata.yaml, ``*.db3`` or ``*.mcap``) with a mapping
          ``input: ros2_bag``.
    mapping : a :class:`LogMapping` or the path of a mapping file; None for our own schema.
    platform : a :class:`Geometry` or a platform file; its gear ratio ``i_G`` converts motor-side
        encoder angles and wheel-side torques. None: the default prototype of PLATFORM.md.
    max_gap_samples : longest allowed time step of the resulting log, in nominal sample periods.

    Returns
    -------
    Log
        ``log.path`` is the input path; converted logs carry ``sidecar['conversion']`` (mapping,
        resampling rate and method, notes).

    Raises
    ------
    LogError
        The input cannot be read or converted, or fails the checks (message names file, column or
        joint, and the first offending row or time).
    MappingError, PlatformFileError
        The mapping or platform file is invalid.
    """
    path = Path(path)
    geometry = platform if isinstance(platform, Geometry) else PROTOTYPE if platform is None else read_platform(platform)
    if mapping is not None and not isinstance(mapping, LogMapping):
        mapping = read_mapping(mapping)
    if not path.exists():
        raise LogError(f"{path}: no such file or directory")
    if is_bag(path):
        if mapping is None:
            raise LogError(f"{path}: a ROS 2 bag needs a mapping file (--mapping) that names its joints; see examples/mappings/ros2_control.yaml")
        return read_bag(path, mapping, geometry, max_gap_samples=max_gap_samples)
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise LogError(f"{path}: unknown input: expected a log ({', '.join(LOG_SUFFIXES)}), a ROS 2 bag directory, .db3 or .mcap")
    if mapping is None:
        return read_log(path, max_gap_samples=max_gap_samples)
    if mapping.input is not InputKind.TABLE:
        raise LogError(f"{path}: the mapping {mapping.path or ''} is for input {mapping.input.value}, but this is a table: use a mapping with input: table")
    return read_mapped_table(path, mapping, geometry, max_gap_samples=max_gap_samples)
