"""Tables (CSV or Parquet) with any column names and units, converted to our schema by a mapping."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from agvdyn.io._convert import (
    DEFAULT_GAP_PERIODS,
    RESAMPLING_METHOD,
    Series,
    assemble_frame,
    check_coupling,
    resample,
    segments_from_ranges,
    uniform_grid,
)
from agvdyn.io.log import MAX_GAP_SAMPLES, SEGMENT_COLUMN, Log, LogError, _numeric_column, _row_text, check_frame, read_table
from agvdyn.io.mapping import InputKind, LogMapping, MappingError, SegmentColumn
from agvdyn.platform import Geometry


def read_mapped_table(
    path: str | os.PathLike,
    mapping: LogMapping,
    geometry: Geometry,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
) -> Log:
    """Convert a CSV or Parquet table with its own column names and units to a checked :class:`Log`.

    Each mapped column is converted to SI units (:meth:`Signal.to_si`, ``geometry.i_G`` for
    gear sides), the time column by ``mapping.time_unit``. Without ``mapping.rate`` the samples
    keep their times; with it they are resampled by linear interpolation onto a uniform time base
    at that rate (segment names: the value of the latest sample at or before each new time).
    Segments come from ``mapping.segments`` (time ranges or a column), else from a ``segment``
    column when the table has one. The file is never modified.

    Raises
    ------
    LogError
        Missing or non-numeric columns, non-finite values, non-increasing time, gaps, mirror
        coupling violated, or the converted log fails the checks of :func:`check_frame`.
    """
    path = Path(path)
    if mapping.input is not InputKind.TABLE:
        raise MappingError(f"{mapping.path or 'mapping'}: input is {mapping.input.value}, but {path} is a table: use a mapping with input: table")
    raw = read_table(path)
    csv = path.suffix.lower() == ".csv"
    needed = {mapping.time_column: "time.column"}
    for s in mapping.signals:
        needed.setdefault(s.source, f"signals.{s.quantity}")
    if isinstance(mapping.segments, SegmentColumn):
        needed.setdefault(mapping.segments.column, "segments.column")
    missing = [(c, k) for c, k in needed.items() if c not in raw.columns]
    if missing:
        listed = ", ".join(f"{c!r} (mapping key {k})" for c, k in missing)
        raise LogError(f"{path}: missing columns {listed}; columns found: {[str(c) for c in raw.columns]}")

    def column(name: str) -> np.ndarray:
        values = _numeric_column(raw[name], str(path), name, csv)
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.argmax(bad))
            raise LogError(f"{path}: column '{name}', {_row_text(str(path), row, csv)}: value {values[row]!r} is not finite: expected a finite number")
        return values

    t_src = column(mapping.time_column) * mapping.time_unit.factor
    dt = np.diff(t_src)
    if (dt <= 0).any():
        i = int(np.argmax(dt <= 0))
        kind = "duplicated" if dt[i] == 0 else "decreasing"
        raise LogError(
            f"{path}: column '{mapping.time_column}', {_row_text(str(path), i + 1, csv)}: {kind} time "
            f"{raw[mapping.time_column].iloc[i + 1]!r} after {raw[mapping.time_column].iloc[i]!r}: expected strictly increasing time"
        )
    signals = {s.quantity: s.to_si(column(s.source), geometry.i_G) for s in mapping.signals}

    seg_src: np.ndarray | None = None
    if isinstance(mapping.segments, SegmentColumn):
        seg_src = _segment_names(raw[mapping.segments.column], dict(mapping.segments.names))
    elif mapping.segments is None and SEGMENT_COLUMN in raw.columns:
        seg_src = _segment_names(raw[SEGMENT_COLUMN], {})

    conversion: dict = {"input": "table", "file": str(path), "mapping": str(mapping.path) if mapping.path else None,
                        "time_column": mapping.time_column, "time_unit": mapping.time_unit.value}
    if mapping.rate is not None:
        period = 1.0 / mapping.rate
        # Default: 5 nominal intervals of the source rows or of the time base, whichever is longer.
        max_gap = mapping.max_gap if mapping.max_gap is not None else DEFAULT_GAP_PERIODS * max(period, float(np.median(dt)))
        series = {q: Series(f"column {mapping.signal(q).source!r} ({q})", t_src, v) for q, v in signals.items()}
        t = uniform_grid(series, period)
        signals = resample(series, t, max_gap, str(path))
        if seg_src is not None:
            seg_src = seg_src[np.searchsorted(t_src, t, side="right") - 1]
        conversion.update(resampled=True, rate=mapping.rate, method=RESAMPLING_METHOD, max_gap=max_gap)
    else:
        t = t_src
        conversion.update(resampled=False)
    segments = segments_from_ranges(t, mapping.segments) if isinstance(mapping.segments, tuple) else seg_src
    coupling = check_coupling(signals, t, mapping, str(path))
    if coupling:
        conversion["coupling_max_deviation"] = coupling
    frame = assemble_frame(t, signals, segments)
    checked = check_frame(frame, f"{path} (converted with {mapping.path or 'mapping'})", max_gap_samples=max_gap_samples)
    return Log(path, checked, {"conversion": conversion})


def _segment_names(column: pd.Series, names: dict[str, str]) -> np.ndarray:
    """Segment names of a column (stripped text, translated by ``names``), None where empty."""
    col = column.astype("string").str.strip()
    col = col.mask(col == "", pd.NA)
    if names:
        col = col.replace(names)
    return col.to_numpy(dtype=object, na_value=None)
