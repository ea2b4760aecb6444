"""One entry point for every command that takes a log: :func:`load_log`."""
from __future__ import annotations

import os
from pathlib import Path

from agvdyn.io.bag import is_bag, read_bag
from agvdyn.io.log import LOG_SUFFIXES, MAX_GAP_SAMPLES, STOP_TOLERANCE, Log, LogError, read_log
from agvdyn.io.mapping import InputKind, LogMapping
from agvdyn.io.mapping_file import read_mapping
from agvdyn.io.table import read_mapped_table
from agvdyn.platform import Geometry, read_platform

PathLike = str | os.PathLike


def load_log(
    path: PathLike,
    mapping: LogMapping | PathLike | None = None,
    platform: Geometry | PathLike | None = None,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
    stop_tolerance: float = STOP_TOLERANCE,
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
        encoder angles and wheel-side torques. None: the mapping's optional ``i_G``; a mapping with
        such signals and neither is refused (no gear ratio is assumed). Unused for our own schema.
    max_gap_samples : longest allowed time step of the resulting log, in nominal sample periods;
        default unlimited (a dropout is read, see :meth:`Log.stretches`).
    stop_tolerance : steering angles beyond +-pi/2 by at most this (rad) are clipped to the stop
        and counted in :attr:`Log.clipped`; further out is an error.

    Returns
    -------
    Log
        ``log.path`` is the input path; converted logs carry ``sidecar['conversion']`` (mapping,
        resampling rate and method, ``i_G`` used and its source, notes such as time gaps left).

    Raises
    ------
    LogError
        The input cannot be read or converted, or fails the checks (message names file, column or
        joint, and the first offending row or time).
    MappingError, PlatformFileError
        The mapping or platform file is invalid; the mapping needs a gear ratio that neither the
        platform nor the mapping gives, or both give different ones.
    """
    path = Path(path)
    geometry = platform if isinstance(platform, Geometry) or platform is None else read_platform(platform)
    if mapping is not None and not isinstance(mapping, LogMapping):
        mapping = read_mapping(mapping)
    if not path.exists():
        raise LogError(f"{path}: no such file or directory")
    if is_bag(path):
        if mapping is None:
            raise LogError(f"{path}: a ROS 2 bag needs a mapping file (--mapping) that names its joints; see examples/mappings/ros2_control.yaml")
        return read_bag(path, mapping, geometry, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance)
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise LogError(f"{path}: unknown input: expected a log ({', '.join(LOG_SUFFIXES)}), a ROS 2 bag directory, .db3 or .mcap")
    if mapping is None:
        return read_log(path, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance)
    if mapping.input is not InputKind.TABLE:
        raise LogError(f"{path}: the mapping {mapping.path or ''} is for input {mapping.input.value}, but this is a table: use a mapping with input: table")
    return read_mapped_table(path, mapping, geometry, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance)
