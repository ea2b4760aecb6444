"""Our log schema (PLATFORM.md "Files"): reading, checking and writing Parquet/CSV logs.

A log has one row per sample, SI units, the columns of :data:`LOG_COLUMNS` and an optional
``segment`` column. Next to ``run.parquet`` an optional YAML sidecar ``run.parquet.yaml``
holds facts about the run (platform, true parameters of a simulation, conversion notes).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from agvdyn._files import write_atomically, write_text_atomically
from agvdyn.platform import Geometry

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
#: Known segment names: the identification sequence of sec. 6.2, the validation manoeuvres of
#: sec. 7, and ``align`` for wheel alignment at rest between segments (mode 1).
SEGMENTS = ("steer_left", "steer_right", "straight", "rotation", "lateral", "lane_change", "align", "lifted_wheel")
#: Mechanical range of the steering angles (PLATFORM.md), rad.
STEERING_LIMIT = math.pi / 2
#: Default tolerance beyond the stops, rad: measured steering angles pass +-pi/2 by their noise
#: (a few mrad, PLATFORM.md); values beyond a stop by at most this much are clipped to the stop
#: (and counted, :attr:`Log.clipped`), values further out are an error.
STOP_TOLERANCE = 0.01
#: Default longest allowed gap between samples, in nominal sample periods (median dt): unlimited.
#: A log with a dropout is read; identification splits it into continuous stretches
#: (:meth:`Log.stretches`). Pass a number to refuse gaps.
MAX_GAP_SAMPLES = math.inf
#: A time step longer than this many nominal steps (median dt) ends a continuous stretch.
STRETCH_GAP_SAMPLES = 3.0
#: Cut-off of the zero-phase filters of the identification, rad/s (PLATFORM.md "Reference values").
FILTER_CUTOFF = 40.0
#: Longest plausible nominal sample time, s: at pi / 40 rad/s the filter cut-off reaches the
#: Nyquist frequency pi / dt. A longer median step is refused (typically time in milliseconds).
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


def sidecar_path(path: str | os.PathLike) -> Path:
    """Path of the YAML sidecar of a log: ``run.parquet`` -> ``run.parquet.yaml``."""
    path = Path(path)
    return path.with_name(path.name + ".yaml")


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
    """Why a nominal (median) time step is implausible for a log, None when it is plausible.

    A step of 0.5 "s" or more looks like milliseconds (2 instead of 0.002); any step beyond
    :data:`MAX_SAMPLE_TIME` puts the 40 rad/s filter cut-off above the Nyquist frequency pi / dt.
    """
    if nominal <= MAX_SAMPLE_TIME:
        return None
    nyquist = math.pi / nominal
    if nominal >= 0.5:
        what = (f"the time column looks like it is in milliseconds: median time step {nominal:.6g} "
                f"(as seconds {1.0 / nominal:.3g} Hz, where a vehicle log at 500 Hz steps by 0.002 s)")
    else:
        what = (f"median time step {nominal:.6g} s ({1.0 / nominal:.4g} Hz) is too long: the {FILTER_CUTOFF:g} rad/s "
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
    max_gap_samples : longest allowed time step in nominal sample periods (median dt); default
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
    if isinstance(max_gap_samples, bool) or not (isinstance(max_gap_samples, (int, float)) and max_gap_samples >= 1):
        raise ValueError(f"max_gap_samples={_show(max_gap_samples)}: expected a number >= 1 (math.inf: no limit)")
    if isinstance(stop_tolerance, bool) or not (isinstance(stop_tolerance, (int, float)) and 0 <= stop_tolerance < math.inf):
        raise ValueError(f"stop_tolerance={_show(stop_tolerance)}: expected a finite number >= 0 (rad)")
    if isinstance(max_sample_time, bool) or not (isinstance(max_sample_time, (int, float)) and max_sample_time > 0):
        raise ValueError(f"max_sample_time={_show(max_sample_time)}: expected a number > 0 (s)")
    missing = [c for c in LOG_COLUMNS if c not in frame.columns]
    if missing:
        raise LogError(
            f"{source}: missing columns {missing}; a log needs {list(LOG_COLUMNS)} "
            f"(optional '{SEGMENT_COLUMN}'), found {[str(c) for c in frame.columns]}"
        )
    n = len(frame)
    if n < 2:
        raise LogError(f"{source}: {n} rows: a log needs at least 2 samples")
    data: dict[str, np.ndarray] = {}
    for col in LOG_COLUMNS:
        data[col] = _numeric_column(frame[col], source, col, csv_rows)
    t = data["t"]
    for col in LOG_COLUMNS:
        bad = ~np.isfinite(data[col])
        if bad.any():
            row = int(np.argmax(bad))
            raise LogError(
                f"{source}: column '{col}', {_row_text(source, row, csv_rows)}: value {data[col][row]:.6g} "
                "is not finite: expected a finite number (NaN, infinite or empty values are not allowed)"
            )
    dt = np.diff(t)
    bad = dt <= 0
    if bad.any():
        i = int(np.argmax(bad))
        kind = "duplicated" if dt[i] == 0 else "decreasing"
        raise LogError(
            f"{source}: column 't', {_row_text(source, i + 1, csv_rows)}: {kind} time "
            f"t = {_time_text(t[i + 1])} after t = {_time_text(t[i])}: expected strictly increasing time"
        )
    nominal = float(np.median(dt))
    if nominal > max_sample_time:
        raise LogError(sample_time_error(source, nominal) or (
            f"{source}: column 't': median time step {nominal:.6g} s is longer than max_sample_time = "
            f"{max_sample_time:.6g} s; {_ms_hint()}"))
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
    for col in ALPHA_COLUMNS:
        mag = np.abs(data[col])
        bad = mag > limit
        if bad.any():
            row = int(np.argmax(bad))
            value = float(data[col][row])
            stop = math.copysign(STEERING_LIMIT, value)
            raise LogError(
                f"{source}: column '{col}', {_row_text(source, row, csv_rows)} (t = {_time_text(t[row])} s): steering "
                f"angle {value:.6g} rad is beyond the mechanical stop {stop:+.6g} rad (pi/2) by {abs(value) - STEERING_LIMIT:.4g} rad, "
                f"more than the stop tolerance {stop_tolerance:.4g} rad within which sensor noise is clipped to the stop: "
                "expected radians in [-pi/2, pi/2] (degrees?); if the sensor really passes the stop by this much, raise the "
                "tolerance (stop_tolerance= of read_log / load_log / Log.from_frame, or agvdyn convert --stop-tolerance RAD)"
            )
        over = mag > STEERING_LIMIT
        n_over = int(np.count_nonzero(over))
        if n_over:
            clipped[col] = n_over
            if clip:
                data[col] = np.clip(data[col], -STEERING_LIMIT, STEERING_LIMIT)
    # One float64 block (no pandas consolidation pass): fast to build and to slice.
    out = pd.DataFrame(np.column_stack([data[c] for c in LOG_COLUMNS]), columns=list(LOG_COLUMNS))
    if SEGMENT_COLUMN in frame.columns:
        out[SEGMENT_COLUMN] = _segment_column(frame[SEGMENT_COLUMN], source, t, csv_rows)
    for col in frame.columns:
        if col not in out.columns:
            out[col] = frame[col].to_numpy()
    return out, clipped


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
        codes = np.asarray(cat.codes)
        lookup = np.array([-1 if v is None else (SEGMENTS.index(v) if v in SEGMENTS else -2) for v in names] + [-1])
        new_codes = lookup[codes]  # code -1 (missing) picks the trailing -1
        unknown = new_codes == -2
        if unknown.any():
            row = int(np.argmax(unknown))
            raise LogError(
                f"{source}: column '{SEGMENT_COLUMN}', {_row_text(source, row, csv_rows)} (t = {_time_text(t[row])} s): "
                f"unknown segment name {names[codes[row]]!r}: expected one of {list(SEGMENTS)} or empty"
            )
        return pd.Categorical.from_codes(new_codes, categories=list(SEGMENTS))
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


@dataclass(frozen=True, eq=False)
class Log:
    """A checked log in our schema.

    Attributes
    ----------
    path : Path or None
        File the log was read from (the original input for converted logs), None if built in memory.
    frame : pandas.DataFrame
        The columns of :data:`LOG_COLUMNS` (float64), ``segment`` (categorical over
        :data:`SEGMENTS`, missing = no segment) when present, then extra columns. Treat as read only.
    sidecar : dict
        Contents of the YAML sidecar, empty when there is none.
    clipped : dict[str, int]
        Rows whose steering angle was beyond a stop (+-pi/2) by at most the stop tolerance and was
        clipped to the stop when the log was read, per alpha column: ``{"alpha_l": n, "alpha_r": m}``
        (zeros when none).
    """

    path: Path | None
    frame: pd.DataFrame
    sidecar: dict[str, Any] = field(default_factory=dict)
    clipped: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ALPHA_COLUMNS, 0))

    def __post_init__(self) -> None:
        # Always both alpha columns, as plain ints (a partial or empty dict counts zeros).
        object.__setattr__(self, "clipped", {c: int(dict(self.clipped or {}).get(c, 0)) for c in ALPHA_COLUMNS})

    @classmethod
    def from_frame(
        cls,
        frame: pd.DataFrame,
        *,
        path: str | os.PathLike | None = None,
        sidecar: dict[str, Any] | None = None,
        max_gap_samples: float = MAX_GAP_SAMPLES,
        stop_tolerance: float = STOP_TOLERANCE,
    ) -> "Log":
        """Check ``frame`` (see :func:`check_frame`) and wrap it in a Log (angles within the stop tolerance clipped and counted)."""
        checked, clipped = _check(frame, "<frame>" if path is None else path, max_gap_samples=max_gap_samples,
                                  stop_tolerance=stop_tolerance)
        return cls(None if path is None else Path(path), checked, dict(sidecar or {}), clipped)

    def _array(self, columns: tuple[str, ...] | str) -> np.ndarray:
        arr = self.frame[list(columns) if isinstance(columns, tuple) else columns].to_numpy(dtype=np.float64)
        arr.setflags(write=False)
        return arr

    @cached_property
    def t(self) -> np.ndarray:
        """Time (N,), s."""
        return self._array("t")

    @cached_property
    def alpha(self) -> np.ndarray:
        """Steering angles (N, 2) = (alpha_l, alpha_r), rad."""
        return self._array(ALPHA_COLUMNS)

    @cached_property
    def beta(self) -> np.ndarray:
        """Wheel angles on the wheel side (N, 4) in wheel order fl, rl, fr, rr, rad."""
        return self._array(BETA_COLUMNS)

    @cached_property
    def torque(self) -> np.ndarray:
        """Motor torques M_mot (N, 4) in wheel order fl, rl, fr, rr, N m (motor side)."""
        return self._array(TORQUE_COLUMNS)

    @cached_property
    def segments(self) -> np.ndarray | None:
        """Segment name of each row (N,) as str, ``""`` for rows in no segment; None without the column."""
        if SEGMENT_COLUMN not in self.frame.columns:
            return None
        cat = pd.Categorical(self.frame[SEGMENT_COLUMN])
        names = np.array([str(c) for c in cat.categories] + [""])
        arr = names[cat.codes]  # code -1 (missing) picks the trailing ""
        arr.setflags(write=False)
        return arr

    @property
    def n_samples(self) -> int:
        return len(self.frame)

    @cached_property
    def sample_time(self) -> float:
        """Nominal sample time: the median of the time steps, s."""
        return float(np.median(np.diff(self.t)))

    @property
    def rate(self) -> float:
        """Nominal sample rate 1 / sample_time, Hz."""
        return 1.0 / self.sample_time

    @property
    def duration(self) -> float:
        """t[-1] - t[0], s."""
        return float(self.t[-1] - self.t[0])

    def _breaks(self, max_step_samples: float) -> np.ndarray:
        """Indices i of the time steps t[i] -> t[i+1] longer than ``max_step_samples`` nominal steps."""
        if isinstance(max_step_samples, bool) or not (isinstance(max_step_samples, (int, float)) and max_step_samples >= 1):
            raise ValueError(f"max_step_samples={_show(max_step_samples)}: expected a number >= 1 (nominal sample periods)")
        return np.flatnonzero(np.diff(self.t) > max_step_samples * self.sample_time)

    def stretches(self, max_step_samples: float = STRETCH_GAP_SAMPLES) -> tuple[slice, ...]:
        """Row slices (half open) of the continuous stretches of the log, in time order.

        The log is split wherever a time step exceeds ``max_step_samples`` times the nominal
        (median) step: a dropout. A log without dropouts is one stretch ``slice(0, n_samples)``.
        """
        cuts = self._breaks(max_step_samples) + 1
        bounds = [0, *cuts.tolist(), self.n_samples]
        return tuple(slice(a, b) for a, b in zip(bounds[:-1], bounds[1:]))

    def gaps(self, max_step_samples: float = STRETCH_GAP_SAMPLES) -> tuple[tuple[float, float], ...]:
        """The dropouts between the stretches of :meth:`stretches`: ``(t before, t after)`` of each, s."""
        t = self.t
        return tuple((float(t[i]), float(t[i + 1])) for i in self._breaks(max_step_samples))

    def segment_runs(self) -> tuple[SegmentRun, ...]:
        """Contiguous runs of rows with the same segment name, in time order (rows in no segment skipped)."""
        seg = self.segments
        if seg is None:
            return ()
        change = np.flatnonzero(seg[1:] != seg[:-1]) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [len(seg)]])
        t = self.t
        return tuple(
            SegmentRun(str(seg[a]), int(a), int(b), float(t[a]), float(t[b - 1]))
            for a, b in zip(starts, stops)
            if seg[a] != ""
        )

    def segment_slices(self) -> dict[str, list[slice]]:
        """For each segment name present, the row slices of its contiguous runs."""
        out: dict[str, list[slice]] = {}
        for run in self.segment_runs():
            out.setdefault(run.name, []).append(run.slice)
        return out


def _log_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in LOG_SUFFIXES:
        raise LogError(f"{path}: unknown log format {path.suffix!r}: expected one of {list(LOG_SUFFIXES)}")
    return suffix


def read_sidecar(path: str | os.PathLike) -> dict[str, Any]:
    """Contents of the YAML sidecar ``<path>.yaml`` of a log, ``{}`` when there is none."""
    side = sidecar_path(path)
    if not side.exists():
        return {}
    try:
        data = yaml.safe_load(side.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise LogError(f"{side}: sidecar is not valid YAML: {exc}") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise LogError(f"{side}: sidecar must hold a mapping at the top level, found {type(data).__name__}")
    return data


def read_table(path: Path) -> pd.DataFrame:
    """Read a Parquet or CSV table as it is (no checks), by suffix."""
    suffix = _log_suffix(path)
    if not path.is_file():
        raise LogError(f"{path}: no such file")
    try:
        if suffix == ".parquet":
            return pd.read_parquet(path)
        return pd.read_csv(path, skipinitialspace=True)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise LogError(f"{path}: cannot be read as {suffix[1:]}: {exc}") from exc


def read_log(
    path: str | os.PathLike,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
    stop_tolerance: float = STOP_TOLERANCE,
) -> Log:
    """Read and check a log in our schema (Parquet or CSV by suffix) and its optional sidecar.

    The file is never modified. See :func:`check_frame` for the checks. Steering angles beyond a
    stop by at most ``stop_tolerance`` are clipped to the stop in the returned log and counted in
    :attr:`Log.clipped`. Dropouts (time gaps) are read; see :meth:`Log.stretches`.

    Parameters
    ----------
    path : path of ``*.parquet`` or ``*.csv``; the sidecar ``<path>.yaml`` is read when present.
    max_gap_samples : longest allowed time step, in nominal sample periods (median dt); default unlimited.
    stop_tolerance : rad beyond the stops +-pi/2 that is clipped (default :data:`STOP_TOLERANCE`).

    Raises
    ------
    LogError
        The file cannot be read or does not satisfy the schema (message names file, column, row).
    """
    path = Path(path)
    frame = read_table(path)
    checked, clipped = _check(frame, path, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance,
                              csv_rows=path.suffix.lower() == ".csv")
    return Log(path, checked, read_sidecar(path), clipped)


def sidecar_platform(log: Log) -> Geometry | None:
    """The platform recorded in a log's sidecar (``platform: {l, b, a, r, i_G, name}``), None without one.

    Raises
    ------
    LogError
        The sidecar has a ``platform`` entry that is not a valid geometry.
    """
    data = log.sidecar.get("platform") if isinstance(log.sidecar, dict) else None
    if data is None:
        return None
    where = sidecar_path(log.path) if log.path is not None else "sidecar"
    keys = ("l", "b", "a", "r", "i_G")
    if not isinstance(data, dict) or any(k not in data for k in keys):
        raise LogError(f"{where}: platform: expected a mapping with {list(keys)}, found {data!r}")
    try:
        return Geometry(**{k: data[k] for k in keys}, name=str(data.get("name", "sidecar")))
    except (TypeError, ValueError) as exc:
        raise LogError(f"{where}: platform: {exc}") from exc


def _plain(value: Any) -> Any:
    """Numpy scalars/arrays and tuples as plain Python for YAML."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def write_log(
    path: str | os.PathLike,
    frame: pd.DataFrame | Log,
    sidecar: dict[str, Any] | None = None,
    *,
    max_gap_samples: float = MAX_GAP_SAMPLES,
    stop_tolerance: float = STOP_TOLERANCE,
) -> Path:
    """Check ``frame`` with the same checks as :func:`read_log` and write it atomically.

    Steering angles within the stop tolerance beyond a stop are written as they are (not
    clipped), so that a later :func:`read_log` counts them.

    Parquet for ``*.parquet``, CSV (header line, full float precision) for ``*.csv``. When
    ``sidecar`` is given it is written atomically to ``<path>.yaml``; when it is None a
    sidecar left over from an earlier file at ``path`` is removed so that it cannot be
    mistaken for this log's. A :class:`Log` is written with its own sidecar unless one is given.

    Returns the path written.
    """
    path = Path(path)
    suffix = _log_suffix(path)
    if isinstance(frame, Log):
        if sidecar is None and frame.sidecar:
            sidecar = frame.sidecar
        frame = frame.frame
    checked, _ = _check(frame, path, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance, clip=False)
    side_text = None
    if sidecar is not None:
        if not isinstance(sidecar, dict):
            raise TypeError(f"sidecar: expected a dict, got {type(sidecar).__name__}")
        side_text = yaml.safe_dump(_plain(sidecar), sort_keys=False)
    if suffix == ".parquet":
        write_atomically(path, lambda tmp: checked.to_parquet(tmp, index=False))
    else:
        write_atomically(path, lambda tmp: checked.to_csv(tmp, index=False))
    side = sidecar_path(path)
    if side_text is not None:
        write_text_atomically(side, side_text)
    else:
        side.unlink(missing_ok=True)
    return path
