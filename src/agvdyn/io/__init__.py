"""Logs in and out: our log schema (Parquet/CSV + YAML sidecar), mapping files, CSV and ROS 2 bags.

Every command that takes a log calls :func:`load_log`.
"""
from agvdyn.io.log import (
    LOG_COLUMNS,
    SEGMENT_COLUMN,
    SEGMENTS,
    Log,
    LogError,
    SegmentRun,
    check_frame,
    read_log,
    read_sidecar,
    sidecar_path,
    write_log,
)

__all__ = [
    "LOG_COLUMNS", "SEGMENT_COLUMN", "SEGMENTS", "Log", "LogError", "SegmentRun",
    "check_frame", "read_log", "read_sidecar", "sidecar_path", "write_log",
]
