"""The log schema (PLATFORM.md "Files"): columns, names, limits, and the checks of a table
against them (:func:`check_frame`); the Log object and its files are in :mod:`agvdyn.io.log`."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from agvdyn._lazy import pandas as pd
from agvdyn.segments_vocabulary import SEGMENTS  # noqa: F401  (the known segment names, re-exported)
from agvdyn.time_base import stamp_interval


#: Required columns of a log, in the order of PLATFORM.md.
LOG_COLUMNS = (
    "t",
    "alpha_l", "alpha_r",
    "beta_fl", "beta_rl", "beta_fr", "beta_rr",
    "m_fl", "m_rl", "m_fr", "m_rr",
)
ALPHA_COLUMNS = ("alpha_l", "alpha_r")
BETA_COLUMNS = ("beta_fl", "beta_rl", "beta_fr", "beta_rr")
TORQUE_COLUMNS = ("m_fl", "m_rl", "m_fr", "m_rr")
#: Name of the optional column naming the experiment phase of each row.
SEGMENT_COLUMN = "segment"
# Known segment names: SEGMENTS, imported above from agvdyn.segments_vocabulary (in the order of the
# codes of the ``segment`` column).
#: Mechanical range of the steering angles (PLATFORM.md), rad.
STEERING_LIMIT = math.pi / 2
#: Default tolerance beyond the stops, rad: measured steering angles pass +-pi/2 by their noise
#: (a few mrad, PLATFORM.md); values beyond a stop by at most this much are clipped to the stop
#: (and counted, :attr:`Log.clipped`), values further out are an error.
STOP_TOLERANCE = 0.01
#: Default longest allowed gap between samples, in nominal sample periods (stamp_interval of t): unlimited.
#: A log with a dropout is read; identification splits it into continuous stretches
#: (:meth:`Log.stretches`). Pass a number to refuse gaps.
MAX_GAP_SAMPLES = math.inf
#: A time step longer than this many nominal steps (stamp_interval of t) ends a continuous stretch.
STRETCH_GAP_SAMPLES = 3.0
#: Cut-off of the zero-phase filters of the identification, rad/s (PLATFORM.md "Reference values").
FILTER_CUTOFF = 40.0
#: Longest plausible nominal sample time, s: at pi / 40 rad/s the filter cut-off reaches the
#: Nyquist frequency pi / dt. A longer nominal step is refused (typically time in milliseconds).
MAX_SAMPLE_TIME = math.pi / FILTER_CUTOFF
#: Suffixes of our own log files.
LOG_SUFFIXES = (".parquet", ".csv")


class LogError(ValueError):
    """A log that cannot be used; the message names file, column and first offending row."""


@dataclass(frozen=True)
class SegmentRun:
    """A contiguous run of rows of one segment: rows ``start:stop`` (half open), times t_start..t_end."""

    name: str
    start: int
    stop: int
    t_start: float
    t_end: float

    @property
    def slice(self) -> slice:
        return slice(self.start, self.stop)

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


def _row_text(source: str, row: int, csv: bool) -> str:
    return f"row {row} (line {row + 2} of the file)" if csv else f"row {row}"


def _show(value: Any) -> str:
    """A keyword value for messages: numbers as ``:.6g`` (never ``np.float64(...)``), anything else as repr."""
    if isinstance(value, (int, float, np.number)) and not isinstance(value, (bool, np.bool_)):
        return f"{float(value):.6g}"
    return repr(value)


def _time_text(value: float) -> str:
    """A time for messages: plain decimal, at most 6 decimals (``0.14``, ``1731000000.123457``), never a numpy repr."""
    value = float(value)
    if not math.isfinite(value):
        return f"{value}"
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def _ms_hint(column: str = "t") -> str:
    """How to fix a time column in milliseconds (the mapping lines of ``agvdyn.io.mapping``)."""
    return (
        f"convert '{column}' to seconds, or read the file with a mapping that declares the time unit: a copy of "
        f"examples/mappings/identity.yaml (input: table) with the line 'time: {{column: {column}, unit: ms}}' "
        "(load_log(path, mapping), agvdyn convert FILE --mapping MAPPING.yaml --out LOG.parquet)"
    )


def sample_time_error(source: str, nominal: float, column: str = "t") -> str | None:
    """Why a nominal time step is implausible for a log, None when it is plausible.

    A step of 0.5 "s" or more looks like milliseconds (2 instead of 0.002); any step beyond
    :data:`MAX_SAMPLE_TIME` puts the 40 rad/s filter cut-off above the Nyquist frequency pi / dt.
    """
    if nominal <= MAX_SAMPLE_TIME:
        return None
    nyquist = math.pi / nominal
    if nominal >= 0.5:
        what = (f"the time column looks like it is in milliseconds: nominal time step {nominal:.6g} "
                f"(as seconds {1.0 / nominal:.3g} Hz, where a vehicle log at 500 Hz steps by 0.002 s)")
    else:
        what = (f"nominal time step {nominal:.6g} s ({1.0 / nominal:.4g} Hz) is too long: the {FILTER_CUTOFF:g} rad/s "
                f"filter cut-off would be above the Nyquist frequency pi/dt = {nyquist:.4g} rad/s "
                f"(a step of at most {MAX_SAMPLE_TIME:.4g} s is needed); if the time is in milliseconds")
    return f"{source}: column '{column}': {what}: {_ms_hint(column)}"


def check_frame(
    frame: pd.DataFrame,
    source: str | os.PathLike = "<frame>",
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
    stop_tolerance: float = STOP_TOLERANCE,
    max_sample_time: float = MAX_SAMPLE_TIME,
    csv_rows: bool = False,
) -> pd.DataFrame:
    """Check a table against the log schema and return a normalised copy.

    The copy has the columns of :data:`LOG_COLUMNS` first (float64), then the ``segment``
    column when present (categorical over :data:`SEGMENTS`, missing = row in no segment), then
    any extra columns unchanged. Steering angles beyond the stops ``+-pi/2`` by at most
    ``stop_tolerance`` (sensor noise) are clipped to the stop in the copy; :func:`read_log` and
    :meth:`Log.from_frame` count them (:attr:`Log.clipped`). The input frame is not modified.

    Parameters
    ----------
    max_gap_samples : longest allowed time step in nominal sample periods (stamp_interval of t); default
        unlimited (a dropout is not an error, see :meth:`Log.stretches`).
    stop_tolerance : rad beyond a stop that is clipped (default :data:`STOP_TOLERANCE`).
    max_sample_time : longest plausible nominal time step, s (default :data:`MAX_SAMPLE_TIME`).
    csv_rows : name rows also by their line in a CSV file.

    Raises
    ------
    LogError
        Missing columns, non-numeric values, NaN or infinite values, ``t`` not strictly
        increasing (duplicated or decreasing), a nominal time step longer than
        ``max_sample_time`` (time in milliseconds), gaps longer than ``max_gap_samples``
        nominal sample periods, steering angles beyond a stop by more than ``stop_tolerance``
        (this also catches degrees), unknown segment names. The message names the source, the
        column and the first offending row.
    """
    return _check(frame, source, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance,
                  max_sample_time=max_sample_time, csv_rows=csv_rows)[0]


def _check(
    frame: pd.DataFrame,
    source: str | os.PathLike,
    *,
    max_gap_samples: float,
    stop_tolerance: float,
    max_sample_time: float = MAX_SAMPLE_TIME,
    csv_rows: bool = False,
    clip: bool = True,
) -> tuple[pd.DataFrame, dict[str, int]]:
    """:func:`check_frame`, also returning the rows clipped to the stops per alpha column.

    With ``clip=False`` (writing) the angles within the tolerance are checked but kept as they are.
    """
    source = str(source)
    if not isinstance(frame, pd.DataFrame):
        raise LogError(f"{source}: expected a pandas DataFrame, got {type(frame).__name__}")
    _check_options(max_gap_samples, stop_tolerance, max_sample_time)
    missing = [c for c in LOG_COLUMNS if c not in frame.columns]
    if missing:
        raise LogError(
            f"{source}: missing columns {missing}; a log needs {list(LOG_COLUMNS)} "
            f"(optional '{SEGMENT_COLUMN}'), found {[str(c) for c in frame.columns]}"
        )
    n = len(frame)
    if n < 2:
        raise LogError(f"{source}: {n} rows: a log needs at least 2 samples")
    block = np.empty((n, len(LOG_COLUMNS)), order="F")  # each column one memcpy (row-major: 0.39 -> 0.08 ms)
    for k, col in enumerate(LOG_COLUMNS):
        block[:, k] = _numeric_column(frame[col], source, col, csv_rows)
    clipped, _ = _check_block(block, source, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance,
                              max_sample_time=max_sample_time, csv_rows=csv_rows, clip=clip)
    # One float64 block (no pandas consolidation pass): fast to build and to slice.
    out = pd.DataFrame(block, columns=list(LOG_COLUMNS), copy=False)
    if SEGMENT_COLUMN in frame.columns:
        out[SEGMENT_COLUMN] = _segment_column(frame[SEGMENT_COLUMN], source, block[:, 0], csv_rows)
    for col in frame.columns:
        if col not in out.columns:
            out[col] = frame[col].to_numpy()
    return out, clipped


@dataclass(frozen=True, eq=False)
class LazyFrame:
    """A checked log's columns before they are made a DataFrame (``Log.frame`` makes it on first
    use): ``block`` (N, 11) float64 in :data:`LOG_COLUMNS` order (column-major), read only; ``segment_codes``
    (N,) codes into :data:`SEGMENTS` (-1: no segment), None without a segment column;
    ``sample_time`` the nominal time step the checks found (:func:`agvdyn.time_base.stamp_interval`)."""

    block: np.ndarray
    segment_codes: np.ndarray | None
    sample_time: float | None = None

    def frame(self) -> pd.DataFrame:
        out = pd.DataFrame(self.block, columns=list(LOG_COLUMNS), copy=False)
        if self.segment_codes is not None:
            out[SEGMENT_COLUMN] = pd.Categorical.from_codes(self.segment_codes, categories=list(SEGMENTS))
        return out


def checked_columns(
    columns: dict[str, np.ndarray],
    segment: tuple[list[str | None], np.ndarray] | None,
    source: str | os.PathLike,
    *,
    max_gap_samples: float,
    stop_tolerance: float,
    clip: bool = True,
    csv_rows: bool = False,
) -> tuple[LazyFrame, dict[str, int]]:
    """The checks of :func:`check_frame` on columns read straight from a file in our schema:
    ``columns`` float64 arrays of every name in :data:`LOG_COLUMNS`, ``segment`` (category names
    or None for missing, int codes with -1 missing) or None. Returns the checked columns (made a
    DataFrame only when one is asked for) and the rows beyond a stop (clipped unless ``clip=False``)."""
    source = str(source)
    _check_options(max_gap_samples, stop_tolerance, MAX_SAMPLE_TIME)
    n = columns[LOG_COLUMNS[0]].shape[0]
    if n < 2:
        raise LogError(f"{source}: {n} rows: a log needs at least 2 samples")
    block = np.empty((n, len(LOG_COLUMNS)))
    for k, col in enumerate(LOG_COLUMNS):
        block[:, k] = columns[col]
    clipped, nominal = _check_block(block, source, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance,
                                    max_sample_time=MAX_SAMPLE_TIME, csv_rows=csv_rows, clip=clip)
    codes = None if segment is None else _segment_codes(segment[0], segment[1], source, block[:, 0], csv_rows)
    block.setflags(write=False)
    return LazyFrame(block, codes, nominal), clipped


def _check_options(max_gap_samples: Any, stop_tolerance: Any, max_sample_time: Any) -> None:
    if isinstance(max_gap_samples, bool) or not (isinstance(max_gap_samples, (int, float)) and max_gap_samples >= 1):
        raise ValueError(f"max_gap_samples={_show(max_gap_samples)}: expected a number >= 1 (math.inf: no limit)")
    if isinstance(stop_tolerance, bool) or not (isinstance(stop_tolerance, (int, float)) and 0 <= stop_tolerance < math.inf):
        raise ValueError(f"stop_tolerance={_show(stop_tolerance)}: expected a finite number >= 0 (rad)")
    if isinstance(max_sample_time, bool) or not (isinstance(max_sample_time, (int, float)) and max_sample_time > 0):
        raise ValueError(f"max_sample_time={_show(max_sample_time)}: expected a number > 0 (s)")


def _check_block(block: np.ndarray, source: str, *, max_gap_samples: float, stop_tolerance: float,
                 max_sample_time: float, csv_rows: bool, clip: bool) -> tuple[dict[str, int], float]:
    """Checks of the float columns (N, 11) in :data:`LOG_COLUMNS` order; angles within the stop
    tolerance clipped in place (``clip``). Returns the clipped rows per alpha column and the
    nominal time step (:func:`agvdyn.time_base.stamp_interval`)."""
    if not np.isfinite(block).all():
        for k, col in enumerate(LOG_COLUMNS):
            bad = ~np.isfinite(block[:, k])
            if bad.any():
                row = int(np.argmax(bad))
                raise LogError(
                    f"{source}: column '{col}', {_row_text(source, row, csv_rows)}: value {block[row, k]:.6g} "
                    "is not finite: expected a finite number (NaN, infinite or empty values are not allowed)"
                )
    t = block[:, 0]
    dt = np.diff(t)
    bad = dt <= 0
    if bad.any():
        i = int(np.argmax(bad))
        kind = "duplicated" if dt[i] == 0 else "decreasing"
        raise LogError(
            f"{source}: column 't', {_row_text(source, i + 1, csv_rows)}: {kind} time "
            f"t = {_time_text(t[i + 1])} after t = {_time_text(t[i])}: expected strictly increasing time"
        )
    nominal = stamp_interval(t, source=f"{source}: column 't'")
    if nominal > max_sample_time:
        raise LogError(sample_time_error(source, nominal) or (
            f"{source}: column 't': nominal time step {nominal:.6g} s is longer than max_sample_time = "
            f"{max_sample_time:.6g} s; {_ms_hint()}"))
    if max_gap_samples < math.inf:
        bad = dt > max_gap_samples * nominal
        if bad.any():
            i = int(np.argmax(bad))
            raise LogError(
                f"{source}: column 't', {_row_text(source, i + 1, csv_rows)}: gap of {dt[i]:.6g} s "
                f"({dt[i] / nominal:.1f} sample periods) from t = {_time_text(t[i])} s to t = {_time_text(t[i + 1])} s: "
                f"expected at most {max_gap_samples:g} nominal sample periods of {nominal:.6g} s"
            )
    clipped = dict.fromkeys(ALPHA_COLUMNS, 0)
    limit = STEERING_LIMIT + stop_tolerance
    for k, col in enumerate(LOG_COLUMNS):
        if col not in ALPHA_COLUMNS:
            continue
        values = block[:, k]
        mag = np.abs(values)
        peak = float(mag.max())
        if peak > limit:
            row = int(np.argmax(mag > limit))
            value = float(values[row])
            stop = math.copysign(STEERING_LIMIT, value)
            raise LogError(
                f"{source}: column '{col}', {_row_text(source, row, csv_rows)} (t = {_time_text(t[row])} s): steering "
                f"angle {value:.6g} rad is beyond the mechanical stop {stop:+.6g} rad (pi/2) by {abs(value) - STEERING_LIMIT:.4g} rad, "
                f"more than the stop tolerance {stop_tolerance:.4g} rad within which sensor noise is clipped to the stop: "
                "expected radians in [-pi/2, pi/2] (degrees?); if the sensor really passes the stop by this much, raise the "
                "tolerance (stop_tolerance= of read_log / load_log / Log.from_frame, or agvdyn convert --stop-tolerance RAD)"
            )
        if peak > STEERING_LIMIT:
            clipped[col] = int(np.count_nonzero(mag > STEERING_LIMIT))
            if clip:
                np.clip(values, -STEERING_LIMIT, STEERING_LIMIT, out=values)
    return clipped, nominal


def _numeric_column(series: pd.Series, source: str, col: str, csv_rows: bool) -> np.ndarray:
    """The column as float64; non-numeric entries are an error naming the first one."""
    if pd.api.types.is_bool_dtype(series.dtype):
        raise LogError(f"{source}: column '{col}' holds booleans: expected numbers")
    if pd.api.types.is_numeric_dtype(series.dtype):
        return series.to_numpy(dtype=np.float64, na_value=np.nan)
    coerced = pd.to_numeric(series, errors="coerce")
    bad = (coerced.isna() & series.notna()).to_numpy()
    if bad.any():
        row = int(np.argmax(bad))
        raise LogError(
            f"{source}: column '{col}', {_row_text(source, row, csv_rows)}: value {series.iloc[row]!r} "
            "is not a number: expected a number in SI units"
        )
    return coerced.to_numpy(dtype=np.float64, na_value=np.nan)


def _segment_column(series: pd.Series, source: str, t: np.ndarray, csv_rows: bool) -> pd.Categorical:
    if isinstance(series.dtype, pd.CategoricalDtype):
        # Check the categories only (Parquet logs written by write_log): O(categories), not O(rows).
        cat = series.array
        names = pd.Series(cat.categories.astype("string")).str.strip()
        names = names.mask(names == "", pd.NA).to_numpy(dtype=object, na_value=None)
        return _segment_categorical(list(names), np.asarray(cat.codes), source, t, csv_rows)
    text = series.astype("string").str.strip()
    # An empty field means "no segment" (for example a transition between phases).
    text = text.mask(text == "", pd.NA)
    unknown = (text.notna() & ~text.isin(SEGMENTS)).to_numpy(dtype=bool)
    if unknown.any():
        row = int(np.argmax(unknown))
        raise LogError(
            f"{source}: column '{SEGMENT_COLUMN}', {_row_text(source, row, csv_rows)} (t = {_time_text(t[row])} s): "
            f"unknown segment name {text.iloc[row]!r}: expected one of {list(SEGMENTS)} or empty"
        )
    return pd.Categorical(text.to_numpy(dtype=object, na_value=None), categories=list(SEGMENTS))


def _segment_categorical(names: list[str | None], codes: np.ndarray, source: str, t: np.ndarray,
                         csv_rows: bool) -> pd.Categorical:
    """Segment labels from category ``names`` (stripped; None for no segment) and ``codes``
    (-1: missing) as a Categorical over :data:`SEGMENTS`; an unknown name is an error naming its first row."""
    return pd.Categorical.from_codes(_segment_codes(names, codes, source, t, csv_rows), categories=list(SEGMENTS))


def _segment_codes(names: list[str | None], codes: np.ndarray, source: str, t: np.ndarray, csv_rows: bool
                   ) -> np.ndarray:
    """Codes into :data:`SEGMENTS` (-1: no segment) of category ``names`` and their ``codes``."""
    names = [None if v is None or not str(v).strip() else str(v).strip() for v in names]
    lookup = np.array([-1 if v is None else (SEGMENTS.index(v) if v in SEGMENTS else -2) for v in names] + [-1],
                      dtype=np.int8)
    new_codes = lookup[codes]  # code -1 (missing) picks the trailing -1
    unknown = new_codes == -2
    if unknown.any():
        row = int(np.argmax(unknown))
        raise LogError(
            f"{source}: column '{SEGMENT_COLUMN}', {_row_text(source, row, csv_rows)} (t = {_time_text(t[row])} s): "
            f"unknown segment name {names[codes[row]]!r}: expected one of {list(SEGMENTS)} or empty"
        )
    return new_codes
