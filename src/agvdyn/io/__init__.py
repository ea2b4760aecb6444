"""Logs in and out: our log schema (Parquet/CSV + YAML sidecar), mapping files, CSV and ROS 2 bags.

Every command that takes a log calls :func:`load_log`; see ``docs/io.md``.
"""
from agvdyn.io.bag import is_bag, read_bag
from agvdyn.io.bag_write import write_bag
from agvdyn.io.load import load_log
from agvdyn.io.log import (
    LOG_COLUMNS,
    SEGMENT_COLUMN,
    SEGMENTS,
    STOP_TOLERANCE,
    STRETCH_GAP_SAMPLES,
    Log,
    LogError,
    SegmentRun,
    check_frame,
    read_log,
    read_sidecar,
    sidecar_path,
    sidecar_platform,
    write_log,
)
from agvdyn.io.mapping import LogMapping, MappingError, Signal
from agvdyn.io.mapping_file import mapping_from_dict, read_mapping
from agvdyn.io.sources import LogFile, load_logs, open_logs
from agvdyn.io.table import read_mapped_table

__all__ = [
    "LOG_COLUMNS", "SEGMENT_COLUMN", "SEGMENTS", "STOP_TOLERANCE", "STRETCH_GAP_SAMPLES", "Log", "LogError", "SegmentRun",
    "check_frame", "read_log", "read_sidecar", "sidecar_path", "sidecar_platform", "write_log",
    "LogMapping", "MappingError", "Signal", "mapping_from_dict", "read_mapping",
    "load_log", "load_logs", "open_logs", "LogFile", "read_mapped_table", "is_bag", "read_bag", "write_bag",
]
