"""Tables (CSV or Parquet) with any column names and units, converted to our schema by a mapping."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from agvdyn._lazy import pandas as pd

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
from agvdyn.io.columns import label_codes
from agvdyn.io.table_columns import table_columns
from agvdyn.io.log import Log, read_table
from agvdyn.io.schema import (
    MAX_GAP_SAMPLES,
    MAX_SAMPLE_TIME,
    SEGMENT_COLUMN,
    STOP_TOLERANCE,
    LogError,
    _numeric_column,
    _row_text,
    _time_text,
)
from agvdyn.io.mapping import InputKind, LogMapping, MappingError, SegmentColumn, TimeUnit, gear_ratio

#: Shortest plausible nominal time step of a mapped table, s (100 kHz): a shorter one means a
#: wrong ``time.unit`` (seconds declared as ms, ...).
MIN_SAMPLE_TIME = 1e-5
from agvdyn.platform import Geometry
from agvdyn.time_base import stamp_interval


def read_mapped_table(
    path: str | os.PathLike,
    mapping: LogMapping,
    geometry: Geometry | None = None,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
    stop_tolerance: float = STOP_TOLERANCE,
) -> Log:
    """Convert a CSV or Parquet table with its own column names and units to a checked :class:`Log`.

    Each mapped column is converted to SI units (:meth:`Signal.to_si`; gear sides by the gear
    ratio of ``geometry``, else the mapping's ``i_G``), the time column by ``mapping.time_unit``.
    Without ``mapping.rate`` the samples keep their times (a dropout stays a time gap); with it
    they are resampled by linear interpolation onto a uniform time base at that rate (segment
    names: the value of the latest sample at or before each new time), leaving out the points
    inside a gap longer than ``mapping.max_gap`` (noted in ``sidecar['conversion']['notes']``).
    Segments come from ``mapping.segments`` (time ranges or a column), else from a ``segment``
    column when the table has one. Steering angles beyond +-pi/2 by at most ``stop_tolerance``
    are clipped and counted (:attr:`Log.clipped`). The file is never modified.

    Raises
    ------
    LogError
        Missing or non-numeric columns, non-finite values, non-increasing time, a time step
        implausible for the declared ``time.unit``, mirror coupling violated, or the converted log
        fails the checks of :func:`check_frame`.
    MappingError
        No gear ratio for signals that need one, or platform and mapping disagree on it.
    """
    path = Path(path)
    if mapping.input is not InputKind.TABLE:
        raise MappingError(f"{mapping.path or 'mapping'}: input is {mapping.input.value}, but {path} is a table: use a mapping with input: table")
    i_G, i_G_source = gear_ratio(mapping, geometry)
    csv = path.suffix.lower() == ".csv"
    needed = {mapping.time_column: "time.column"}
    for s in mapping.signals:
        needed.setdefault(s.source, f"signals.{s.quantity}")
    label_column = mapping.segments.column if isinstance(mapping.segments, SegmentColumn) else None
    if label_column is not None:
        needed.setdefault(label_column, "segments.column")
    numbers = [c for c in needed if c != label_column]
    raw: dict[str, np.ndarray] | pd.DataFrame | None = None
    if path.is_file() and label_column not in {s.source for s in mapping.signals}:  # plain tables: no pandas
        raw = table_columns(path, numbers, [label_column or SEGMENT_COLUMN])
    if raw is None:
        raw = read_table(path)
    found = list(raw) if isinstance(raw, dict) else [str(c) for c in raw.columns]
    missing = [(c, k) for c, k in needed.items() if c not in found]
    if missing and isinstance(raw, dict):  # name every column found: read the header again with pandas
        found = [str(c) for c in read_table(path).columns]
    if missing:
        listed = ", ".join(f"{c!r} (mapping key {k})" for c, k in missing)
        raise LogError(f"{path}: missing columns {listed}; columns found: {found}")

    def column(name: str) -> np.ndarray:
        values = raw[name] if isinstance(raw, dict) else _numeric_column(raw[name], str(path), name, csv)
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.argmax(bad))
            raise LogError(f"{path}: column '{name}', {_row_text(str(path), row, csv)}: value {values[row]:.6g} is not finite: expected a finite number")
        return values

    t_src = column(mapping.time_column) * mapping.time_unit.factor
    dt = np.diff(t_src)
    if (dt <= 0).any():
        i = int(np.argmax(dt <= 0))
        kind = "duplicated" if dt[i] == 0 else "decreasing"
        raise LogError(
            f"{path}: column '{mapping.time_column}', {_row_text(str(path), i + 1, csv)}: {kind} time "
            f"{_time_text(t_src[i + 1] / mapping.time_unit.factor)} after {_time_text(t_src[i] / mapping.time_unit.factor)} "
            f"({mapping.time_unit.value}): expected strictly increasing time"
        )
    source_step = stamp_interval(t_src, source=f"{path}: column '{mapping.time_column}'") if dt.size else 0.0
    _check_time_unit(path, mapping, source_step)
    signals = {s.quantity: s.to_si(column(s.source), i_G) for s in mapping.signals}

    seg_src: np.ndarray | None = None
    if isinstance(mapping.segments, SegmentColumn):
        seg_src = _segment_names(raw[label_column], dict(mapping.segments.names))
    elif mapping.segments is None and SEGMENT_COLUMN in found:
        seg_src = _segment_names(raw[SEGMENT_COLUMN], {})

    conversion: dict = {"input": "table", "file": str(path), "mapping": str(mapping.path) if mapping.path else None,
                        "time_column": mapping.time_column, "time_unit": mapping.time_unit.value,
                        "i_G": i_G, "i_G_source": i_G_source}
    notes: list[str] = []
    if mapping.rate is not None:
        period = 1.0 / mapping.rate
        # Default: 5 nominal intervals of the source rows or of the time base, whichever is longer.
        max_gap = mapping.max_gap if mapping.max_gap is not None else DEFAULT_GAP_PERIODS * max(period, source_step)
        series = {q: Series(f"column {mapping.signal(q).source!r} ({q})", t_src, v) for q, v in signals.items()}
        grid = uniform_grid(series, period)
        keep, gap_notes = gap_points(series, grid, max_gap)
        notes.extend(gap_notes)
        t = grid[keep]
        signals = {k: v[keep] for k, v in resample(series, grid).items()}
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
    conversion["notes"] = notes
    return converted_log(path, mapping, t, signals, segments, conversion, max_gap_samples=max_gap_samples,
                         stop_tolerance=stop_tolerance)


def _check_time_unit(path: Path, mapping: LogMapping, nominal: float) -> None:
    """Refuse a nominal time step that the declared ``time.unit`` makes implausible, suggesting the unit that fits."""
    if MIN_SAMPLE_TIME <= nominal <= MAX_SAMPLE_TIME or nominal <= 0:
        return
    raw_step = nominal / mapping.time_unit.factor
    fits = [u for u in TimeUnit if MIN_SAMPLE_TIME <= raw_step * u.factor <= MAX_SAMPLE_TIME]
    # Prefer the unit that puts the step nearest 2 ms (the paper's sample time).
    fits.sort(key=lambda u: abs(np.log(raw_step * u.factor / 2e-3)))
    hint = (f"the column looks like it is in {fits[0].value}: write 'time: {{column: {mapping.time_column}, unit: {fits[0].value}}}'"
            if fits else f"no time unit gives a plausible step; check the column 'time.column: {mapping.time_column}'")
    kind = "too long" if nominal > MAX_SAMPLE_TIME else "too short"
    limit = (f"the 40 rad/s filter cut-off would be above the Nyquist frequency (at most {MAX_SAMPLE_TIME:.4g} s)"
             if nominal > MAX_SAMPLE_TIME else f"faster than {1 / MIN_SAMPLE_TIME:.6g} Hz is not a vehicle log")
    milliseconds = " (time in milliseconds?)" if any(u is TimeUnit.MS for u in fits[:1]) else ""
    of_mapping = f" of the mapping {mapping.path}" if mapping.path is not None else ""
    raw = f" ({raw_step:.6g} {mapping.time_unit.value})" if mapping.time_unit is not TimeUnit.S else ""
    raise LogError(
        f"{path}: column '{mapping.time_column}' with time.unit: {mapping.time_unit.value}{of_mapping} "
        f"gives a nominal time step of {nominal:.6g} s{raw}, {kind}{milliseconds}: {limit}; {hint} in the mapping"
    )


def _segment_names(column: pd.Series | np.ndarray, names: dict[str, str]) -> np.ndarray:
    """Segment names of a column (stripped text, translated by ``names``), None where empty."""
    if isinstance(column, np.ndarray):  # read by table_columns: stripped already, None where empty
        if not names:
            return column
        distinct, codes = label_codes(column)
        return np.array([names.get(v, v) for v in distinct] + [None], dtype=object)[codes]
    col = column.astype("string").str.strip()
    col = col.mask(col == "", pd.NA)
    if names:
        col = col.replace(names)
    return col.to_numpy(dtype=object, na_value=None)
