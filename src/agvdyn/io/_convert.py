"""Shared steps of converting foreign data to our schema: resampling, segments, coupling check."""
from __future__ import annotations

from collections.abc import Mapping as MappingABC
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agvdyn.io.columns import label_codes
from agvdyn.io.log import LOG_COLUMNS, Log, LogError
from agvdyn.io.schema import checked_columns
from agvdyn.io.mapping import HEADING_QUANTITIES, LogMapping, SegmentRange

#: How signals are brought onto one uniform time base (stated in sidecars and docs/io.md).
RESAMPLING_METHOD = (
    "linear interpolation of every signal (angles and torques) onto a uniform time base "
    "over the time range common to all signals; error bound h^2/8 max|f''| for a sample interval h"
)
#: Default longest interpolated interval, in periods of the uniform time base.
DEFAULT_GAP_PERIODS = 5.0


@dataclass(frozen=True)
class Series:
    """Samples of one signal at increasing times (s, relative to a common origin)."""

    label: str
    times: np.ndarray
    values: np.ndarray


def uniform_grid(series: MappingABC[str, Series], period: float) -> np.ndarray:
    """Uniform times ``start + k period`` over the range common to all series."""
    start = max(float(s.times[0]) for s in series.values())
    end = min(float(s.times[-1]) for s in series.values())
    if end <= start:
        labels = ", ".join(f"{s.label} [{s.times[0]:.6g}, {s.times[-1]:.6g}] s" for s in series.values())
        raise LogError(f"the signals have no common time range to resample on: {labels}")
    n = int(np.floor((end - start) / period * (1 + 1e-12) + 1e-9)) + 1
    return start + np.arange(n) * period


def resample(series: MappingABC[str, Series], grid: np.ndarray) -> dict[str, np.ndarray]:
    """Linear interpolation of each series onto ``grid`` (see :data:`RESAMPLING_METHOD`).

    Every grid point is interpolated, also inside gaps; :func:`gap_points` says which points
    lie inside a gap too long to be interpolated over.
    """
    return {key: np.interp(grid, s.times, s.values) for key, s in series.items()}


def gap_points(
    series: MappingABC[str, Series],
    grid: np.ndarray,
    max_gap: float,
    time_note: str = "",
) -> tuple[np.ndarray, list[str]]:
    """Grid points that may be interpolated, and a note per gap that may not.

    A point strictly between two samples of a series that are more than ``max_gap`` apart is
    not interpolated over (the data there are missing, not sparse): it is left out, so that the
    converted log has a time gap there (a dropout, :meth:`agvdyn.io.Log.stretches`).

    Returns
    -------
    keep : (len(grid),) bool, False at the points inside a gap of any series.
    notes : one text per gap (signals with the same gap named together), in time order.
    """
    keep = np.ones(grid.size, dtype=bool)
    found: dict[tuple[float, float], list[str]] = {}
    lo, hi = grid[0], grid[-1]
    for s in series.values():
        dt = np.diff(s.times)
        for i in np.flatnonzero((dt > max_gap) & (s.times[1:] > lo) & (s.times[:-1] < hi)):
            a, b = float(s.times[i]), float(s.times[i + 1])
            keep[np.searchsorted(grid, a, side="right"):np.searchsorted(grid, b, side="left")] = False
            found.setdefault((a, b), []).append(s.label)
    notes = []
    for (a, b), labels in sorted(found.items()):
        left = int(np.count_nonzero((grid > a) & (grid < b)))
        who = f"all {len(labels)} signals" if len(labels) == len(series) > 1 else ", ".join(labels)
        notes.append(
            f"{who}: no sample between t = {a:.6f} s and t = {b:.6f} s{time_note} "
            f"(gap {b - a:.6g} s, longer than max_gap {max_gap:.6g} s): not interpolated over, "
            f"{left} points of the time base left out (the log has a time gap there)"
        )
    return keep, notes


#: Tolerance of segment range boundaries, s: the resolution of bag stamps (1 ns), so that a row
#: at t = 12.999999999999998 on a computed time base belongs to a range starting at 13.0.
BOUNDARY_TOLERANCE = 1e-9


def segments_from_ranges(t: np.ndarray, ranges: tuple[SegmentRange, ...]) -> np.ndarray:
    """Segment name per row from time ranges ``[start, end)`` (boundaries within 1 ns); None outside."""
    names = np.full(len(t), None, dtype=object)
    eps = BOUNDARY_TOLERANCE
    for r in ranges:
        names[(t >= r.start - eps) & (t < r.end - eps)] = r.name
    return names


def check_coupling(signals: dict[str, np.ndarray], t: np.ndarray, mapping: LogMapping, source: str) -> dict[str, float]:
    """Check mapped rear headings against the mirror coupling heading_rl = -alpha_l, heading_rr = -alpha_r.

    Returns the largest deviation of each checked side (rad).

    Raises
    ------
    LogError
        A deviation beyond ``mapping.coupling_tolerance``: a wrong mapping (joint, sign, unit) or a
        broken steering coupling.
    """
    worst: dict[str, float] = {}
    for heading, alpha in HEADING_QUANTITIES.items():
        if heading not in signals:
            continue
        dev = np.abs(signals[heading] + signals[alpha])
        i = int(np.argmax(dev))
        worst[heading] = float(dev[i])
        if dev[i] > mapping.coupling_tolerance:
            src = mapping.signal(heading).source
            raise LogError(
                f"{source}: {src} ({heading}) = {signals[heading][i]:.6g} rad at t = {t[i]:.6f} s but the mirror "
                f"coupling of PLATFORM.md requires {heading} = -{alpha} = {-signals[alpha][i]:.6g} rad "
                f"(deviation {dev[i]:.3g} rad > tolerance {mapping.coupling_tolerance:g} rad): this means a wrong "
                "mapping (joint names, signs, units) or a broken steering coupling"
            )
    return worst


def converted_log(path: Path, mapping: LogMapping, t: np.ndarray, signals: dict[str, np.ndarray],
                  segments: np.ndarray | None, conversion: dict, *, max_gap_samples: float,
                  stop_tolerance: float) -> Log:
    """The checked :class:`Log` of SI signals (headings dropped) and optional segment names, with
    ``conversion`` as its sidecar (rows clipped to the stops added): no DataFrame on the way."""
    columns = {"t": t, **{c: signals[c] for c in LOG_COLUMNS[1:]}}
    segment = None if segments is None else label_codes(segments)
    lazy, clipped = checked_columns(columns, segment, f"{path} (converted with {mapping.path or 'mapping'})",
                                    max_gap_samples=max_gap_samples, stop_tolerance=stop_tolerance)
    if any(clipped.values()):
        conversion["clipped_to_stops"] = dict(clipped)
    return Log.from_checked(path, lazy, {"conversion": conversion}, clipped)
