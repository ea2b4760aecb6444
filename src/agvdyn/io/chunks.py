"""Long logs in our schema read a piece at a time: Parquet batches (row groups) or CSV chunks,
each piece with ``overlap`` rows of its neighbours on both sides, so that filters started in the
overlap have settled inside the piece. Memory depends on the piece size, not on the log's length.
"""
from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

from agvdyn._lazy import pandas as pd

from agvdyn.io.log import STOP_TOLERANCE, Log, LogError, _log_suffix, read_sidecar
from agvdyn.io.parquet import parquet_metadata

__all__ = ["CHUNK_ROWS", "CHUNK_OVERLAP", "log_rows_count", "is_long_log", "log_pieces"]

#: Rows of a piece (131 s at 500 Hz; about 100 MB of working memory while it is identified).
CHUNK_ROWS = 1 << 16
#: Rows of the neighbours on each side of a piece (4 s at 500 Hz: filter transients, edges and guards).
CHUNK_OVERLAP = 2000


def log_rows_count(path: str | os.PathLike) -> int | None:
    """Rows of a Parquet log from its metadata (no data read); None for CSV."""
    path = Path(path)
    if _log_suffix(path) != ".parquet":
        return None
    try:
        return int(parquet_metadata(path).num_rows)
    except Exception as exc:  # noqa: BLE001 - any pyarrow failure: the file is not readable Parquet
        raise LogError(f"{path}: cannot be read as parquet: {exc}") from exc


def is_long_log(path: str | os.PathLike, rows: int | None = None) -> bool:
    """Whether a log in our schema is read in pieces: more than ``2 rows`` rows (Parquet), or a CSV
    file larger than ``2 rows`` lines of about 100 bytes."""
    path = Path(path)
    rows = CHUNK_ROWS if rows is None else rows
    if path.suffix.lower() not in (".parquet", ".csv") or not path.is_file():
        return False
    count = log_rows_count(path)
    return count > 2 * rows if count is not None else path.stat().st_size > 2 * rows * 100


def _frames(path: Path, rows: int) -> Iterator[pd.DataFrame]:
    """Frames of about ``rows`` rows: Parquet row groups read one at a time (split or joined to that
    size; nothing else of the file is held), CSV chunks."""
    if _log_suffix(path) != ".parquet":
        yield from pd.read_csv(path, skipinitialspace=True, chunksize=rows)
        return
    import pyarrow as pa
    import pyarrow.parquet as pq

    file = pq.ParquetFile(path, pre_buffer=False)
    parts: list[pa.Table] = []
    held = 0
    for i in range(file.num_row_groups):
        group = file.read_row_group(i)
        for start in range(0, group.num_rows, rows):
            part = group.slice(start, rows)
            parts.append(part)
            held += part.num_rows
            if held >= rows:
                yield pa.concat_tables(parts).to_pandas()
                parts, held = [], 0
    if parts:
        yield pa.concat_tables(parts).to_pandas()


def log_pieces(path: str | os.PathLike, *, rows: int | None = None, overlap: int | None = None,
               stop_tolerance: float = STOP_TOLERANCE) -> Iterator[tuple[Log, slice]]:
    """Consecutive pieces of a log: ``(log, core)``, ``log`` the piece with up to ``overlap`` rows of
    each neighbour (checked like :func:`agvdyn.io.read_log`), ``core`` the rows that are its own.
    Every row of the file is in exactly one core; the file is never modified."""
    path = Path(path)
    rows = CHUNK_ROWS if rows is None else rows
    overlap = CHUNK_OVERLAP if overlap is None else overlap
    if rows < 1 or overlap < 0:
        raise ValueError(f"rows={rows}, overlap={overlap}: expected rows >= 1 and overlap >= 0")
    sidecar = read_sidecar(path)
    tail = None
    pending = None
    for frame in _frames(path, rows):
        if pending is not None:
            yield _piece(path, sidecar, tail, pending, frame.iloc[:overlap], stop_tolerance)
            tail = pending.iloc[-overlap:] if overlap else pending.iloc[:0]
        pending = frame
    if pending is not None:
        yield _piece(path, sidecar, tail, pending, None, stop_tolerance)


def _piece(path: Path, sidecar: dict, before: pd.DataFrame | None, own: pd.DataFrame, after: pd.DataFrame | None,
           stop_tolerance: float) -> tuple[Log, slice]:
    parts = [p for p in (before, own, after) if p is not None and len(p)]
    frame = pd.concat(parts, ignore_index=True) if len(parts) > 1 else own.reset_index(drop=True)
    start = 0 if before is None else len(before)
    log = Log.from_frame(frame, path=path, sidecar=sidecar, stop_tolerance=stop_tolerance)
    return log, slice(start, start + len(own))
