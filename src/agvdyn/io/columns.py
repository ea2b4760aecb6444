"""A log given as numpy columns (``{"t": ..., "alpha_l": ..., ..., "segment": labels}``), checked
like a DataFrame (:func:`agvdyn.io.schema.check_frame`) without pandas: what
:func:`agvdyn.io.log.write_log` writes for ``agvdyn simulate`` (issue 28: pandas was ~0.15 s of its
start-up)."""
from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from agvdyn.io.schema import LOG_COLUMNS, SEGMENT_COLUMN, LazyFrame, LogError, checked_columns

__all__ = ["checked_arrays", "label_codes"]


def label_codes(labels: Any) -> tuple[list[Any], np.ndarray]:
    """``(names, codes)`` of a column of segment labels (N,): the distinct labels in order of first
    appearance and each row's index into them (int64), found run by run (the labels of a log change
    a few dozen times, not per row)."""
    labels = np.asarray(labels)
    n = labels.shape[0]
    if n == 0:
        return [], np.zeros(0, dtype=np.int64)
    starts = np.concatenate([[0], np.flatnonzero(labels[1:] != labels[:-1]) + 1])
    run_labels = labels[starts].tolist()
    names = list(dict.fromkeys(run_labels))
    index = {name: i for i, name in enumerate(names)}
    run_codes = np.array([index[v] for v in run_labels], dtype=np.int64)
    return names, np.repeat(run_codes, np.diff(np.append(starts, n)))


def _float_column(values: Any, source: str, name: str, n: int | None) -> np.ndarray:
    """The column as a float64 array; booleans, non-numbers and a length unlike the others are errors."""
    arr = np.asarray(values)
    if arr.dtype == bool:
        raise LogError(f"{source}: column '{name}' holds booleans: expected numbers")
    if arr.dtype.kind not in "fiu":
        raise LogError(f"{source}: column '{name}' holds {arr.dtype} values: expected numbers in SI units")
    if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
        raise LogError(f"{source}: column '{name}' has shape {arr.shape}: expected ({n if n is not None else 'N'},) "
                       f"like column '{LOG_COLUMNS[0]}'")
    return arr.astype(np.float64, copy=False)


def checked_arrays(columns: Mapping[str, Any], source: str | os.PathLike, *, max_gap_samples: float,
                   stop_tolerance: float, clip: bool = True) -> tuple[LazyFrame, dict[str, int]]:
    """The checks of :func:`agvdyn.io.schema.check_frame` on a log given as columns: every name of
    :data:`LOG_COLUMNS` (numbers) and optionally ``segment`` (labels: a known segment name, ``""``
    or None for rows in no segment). Returns the checked columns (:class:`LazyFrame`) and the rows
    beyond a stop per alpha column (clipped to it unless ``clip=False``, as when writing).

    Raises
    ------
    LogError
        A missing or extra column, a column of another length or not of numbers, or any failure of the
        schema's checks (the message names the source, the column and the first offending row).
    """
    source = str(source)
    missing = [c for c in LOG_COLUMNS if c not in columns]
    extra = [str(c) for c in columns if c not in LOG_COLUMNS and c != SEGMENT_COLUMN]
    if missing or extra:
        raise LogError(f"{source}: columns {list(map(str, columns))}: missing {missing}, unexpected {extra}; a log "
                       f"given as arrays needs exactly {list(LOG_COLUMNS)} (optional '{SEGMENT_COLUMN}')")
    first = _float_column(columns[LOG_COLUMNS[0]], source, LOG_COLUMNS[0], None)
    arrays = {c: _float_column(columns[c], source, c, first.shape[0]) for c in LOG_COLUMNS}
    segment = None
    if SEGMENT_COLUMN in columns:
        labels = np.asarray(columns[SEGMENT_COLUMN])
        if labels.shape != first.shape:
            raise LogError(f"{source}: column '{SEGMENT_COLUMN}' has shape {labels.shape}: expected {first.shape} "
                           f"like column '{LOG_COLUMNS[0]}'")
        segment = label_codes(labels)
    return checked_columns(arrays, segment, source, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance,
                           clip=clip)
