"""Our log schema (PLATFORM.md "Files"): reading, checking and writing Parquet/CSV logs.

A log has one row per sample, SI units, the columns of :data:`LOG_COLUMNS` and an optional
``segment`` column. Next to ``run.parquet`` an optional YAML sidecar ``run.parquet.yaml``
holds facts about the run (platform, true parameters of a simulation, conversion notes).
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from agvdyn._lazy import pandas as pd
import yaml

from agvdyn._files import write_atomically, write_text_atomically
from agvdyn.platform import Geometry
from agvdyn.time_base import stamp_interval
from agvdyn.io.columns import checked_arrays, label_codes
from agvdyn.io.table_columns import csv_columns
from agvdyn.io.parquet import (  # noqa: F401  (re-exported)
    our_parquet_columns, parquet_metadata, write_our_parquet, write_parquet_columns)
from agvdyn.io.sidecar import LazySidecar, sidecar_text
from agvdyn.io.schema import (  # noqa: F401  (the schema's names, re-exported)
    LOG_COLUMNS,
    ALPHA_COLUMNS,
    BETA_COLUMNS,
    TORQUE_COLUMNS,
    SEGMENT_COLUMN,
    SEGMENTS,
    STEERING_LIMIT,
    STOP_TOLERANCE,
    MAX_GAP_SAMPLES,
    STRETCH_GAP_SAMPLES,
    FILTER_CUTOFF,
    MAX_SAMPLE_TIME,
    LOG_SUFFIXES,
    LogError,
    SegmentRun,
    LazyFrame,
    check_frame,
    checked_columns,
    sample_time_error,
    _check,
    _show,
)


def sidecar_path(path: str | os.PathLike) -> Path:
    """Path of the YAML sidecar of a log: ``run.parquet`` -> ``run.parquet.yaml``."""
    path = Path(path)
    return path.with_name(path.name + ".yaml")


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

    def __getattribute__(self, name: str) -> Any:
        value = object.__getattribute__(self, name)
        if name == "sidecar" and type(value) is LazySidecar:  # read_log keeps a plain sidecar as text
            value = value.parse()
            object.__setattr__(self, "sidecar", value)
        elif name == "frame" and type(value) is LazyFrame:  # and our Parquet's columns as numpy arrays
            value = value.frame()
            object.__setattr__(self, "frame", value)
        return value

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

    @classmethod
    def from_checked(cls, path: Path | None, lazy: LazyFrame, sidecar: Any, clipped: dict[str, int]) -> "Log":
        """A Log of columns already checked (:func:`checked_columns`): no DataFrame until ``frame`` is asked for."""
        log = cls(path, lazy, sidecar, clipped)  # type: ignore[arg-type]
        object.__setattr__(log, "_block", lazy.block)
        log.__dict__["sample_time"] = lazy.sample_time  # the checks' nominal step: not taken twice
        return log

    def _array(self, columns: tuple[str, ...] | str) -> np.ndarray:
        block = self.__dict__.get("_block")
        if block is not None:  # read by read_log: views of the one float block the frame shares
            names = columns if isinstance(columns, tuple) else (columns,)
            first = LOG_COLUMNS.index(names[0])
            if names == LOG_COLUMNS[first:first + len(names)]:
                return block[:, first] if isinstance(columns, str) else block[:, first:first + len(names)]
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
        lazy = object.__getattribute__(self, "frame")
        if type(lazy) is LazyFrame:  # read straight from Parquet: the codes, without making the DataFrame
            if lazy.segment_codes is None:
                return None
            arr = np.array([*SEGMENTS, ""])[lazy.segment_codes]  # code -1 (missing) picks the trailing ""
            arr.setflags(write=False)
            return arr
        if SEGMENT_COLUMN not in self.frame.columns:
            return None
        cat = pd.Categorical(self.frame[SEGMENT_COLUMN])
        names = np.array([str(c) for c in cat.categories] + [""])
        arr = names[cat.codes]  # code -1 (missing) picks the trailing ""
        arr.setflags(write=False)
        return arr

    @property
    def n_samples(self) -> int:
        return len(self.t)

    @cached_property
    def sample_time(self) -> float:
        """Nominal sample time, s: :func:`agvdyn.time_base.stamp_interval` of ``t`` (the uniform step of
        a resampled log; unbiased under jitter and dropouts otherwise)."""
        return stamp_interval(self.t, source=f"{self.path or 'log'}: column 't'")

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
        step (:attr:`sample_time`): a dropout. A log without dropouts is one stretch ``slice(0, n_samples)``.
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
    data = sidecar_text(sidecar_path(path))
    return data.parse() if isinstance(data, LazySidecar) else data


def sidecar_value(log: Any, key: str, default: Any = None) -> Any:
    """The top-level entry ``key`` of a log's sidecar (``default`` without one), without parsing the
    rest of a sidecar :func:`read_log` kept as text."""
    raw = getattr(log, "__dict__", {}).get("sidecar")
    if isinstance(raw, LazySidecar):
        return raw.get(key, default)
    sidecar = getattr(log, "sidecar", None)
    return sidecar.get(key, default) if isinstance(sidecar, dict) else default


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
    max_gap_samples : longest allowed time step, in nominal sample periods (:attr:`Log.sample_time`); default unlimited.
    stop_tolerance : rad beyond the stops +-pi/2 that is clipped (default :data:`STOP_TOLERANCE`).

    Raises
    ------
    LogError
        The file cannot be read or does not satisfy the schema (message names file, column, row).
    """
    path = Path(path)
    columns = our_parquet_columns(path) if path.suffix.lower() == ".parquet" and path.is_file() else None
    if columns is not None:  # our own Parquet: columns straight to numpy, no DataFrame on the way
        lazy, clipped = checked_columns(*columns, path, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance)
        return Log.from_checked(path, lazy, sidecar_text(sidecar_path(path)), clipped)
    plain = csv_columns(path, LOG_COLUMNS, [SEGMENT_COLUMN], exactly=True) if path.suffix.lower() == ".csv" \
        and path.is_file() else None
    if plain is not None and all(c in plain for c in LOG_COLUMNS):  # a plain CSV of our columns: no pandas
        segment = label_codes(plain.pop(SEGMENT_COLUMN)) if SEGMENT_COLUMN in plain else None
        lazy, clipped = checked_columns(plain, segment, path, max_gap_samples=max_gap_samples,
                                        stop_tolerance=stop_tolerance, csv_rows=True)
        return Log.from_checked(path, lazy, sidecar_text(sidecar_path(path)), clipped)
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
    data = sidecar_value(log, "platform")
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
    frame: pd.DataFrame | Log | Mapping[str, Any],
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
    ``frame`` may also be a mapping of numpy columns (:func:`agvdyn.io.columns.checked_arrays`: exactly
    the log's columns, ``segment`` as labels): checked and written without pandas (a Parquet file
    byte for byte the one of the same DataFrame).

    Returns the path written.
    """
    path = Path(path)
    suffix = _log_suffix(path)
    if isinstance(frame, Log):
        if sidecar is None and frame.sidecar:
            sidecar = frame.sidecar
        frame = frame.frame
    if isinstance(frame, Mapping):
        checked, _ = checked_arrays(frame, path, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance,
                                    clip=False)
    else:
        checked, _ = _check(frame, path, max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance, clip=False)
    side_text = None
    if sidecar is not None:
        if not isinstance(sidecar, dict):
            raise TypeError(f"sidecar: expected a dict, got {type(sidecar).__name__}")
        side_text = yaml.safe_dump(_plain(sidecar), sort_keys=False)
    if suffix == ".parquet":
        write = write_parquet_columns if isinstance(checked, LazyFrame) else write_our_parquet
        write_atomically(path, lambda tmp: write(tmp, checked))
    else:
        table = checked.frame() if isinstance(checked, LazyFrame) else checked
        write_atomically(path, lambda tmp: table.to_csv(tmp, index=False))
    side = sidecar_path(path)
    if side_text is not None:
        write_text_atomically(side, side_text)
    else:
        side.unlink(missing_ok=True)
    return path
