"""Pre-flight check of identification logs (``agvdyn inspect``): is this data good enough, and if
not, which experiment is missing for which parameter.

Per file: timing, dropouts, the motion-mode timeline the identification will use (from the
filtered configuration, next to the labels), rows clipped at the steering stops, wheel slip,
and the account of the rows. Over all files: how well each parameter is excited by the rows
kept (rank, variance inflation, relative standard deviation of a trial fit), and a verdict.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.identification import (
    DEFAULT_FIXED,
    EXCITATION,
    IdentificationSettings,
    LeastSquares,
    LogRows,
    dependent_parameters,
    row_passes,
    variance_inflation,
)
from agvdyn.identification.excitation import COLLINEAR_RELATIVE_STD, ExcitationCheck
from agvdyn.identification.fit import columns, estimate, normal_equations
from agvdyn.io.summary import LogSummary, ModeRun, summarize_log
from agvdyn.kinematics import Mode
from agvdyn.platform import PARAMETER_NAMES, Geometry
from agvdyn.signals import runs

__all__ = ["Excitation", "FileCheck", "Preflight", "TimelineRow", "merge_short_runs", "preflight"]


@dataclass(frozen=True)
class Excitation:
    """How well the rows kept excite one parameter: ``status`` is ``ok``, ``weak``, ``not excited`` or ``fixed``."""

    name: str
    status: str
    inflation: float = math.nan
    relative_std: float = math.nan

    @property
    def excited_by(self) -> str:
        return EXCITATION.get(self.name, "")

    def to_dict(self) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"status": self.status, "variance_inflation": num(self.inflation),
                "relative_std": num(self.relative_std), "excited_by": self.excited_by}


@dataclass(frozen=True)
class TimelineRow:
    """One row of a printed mode timeline: ``runs`` consecutive detected runs from ``t_start`` to
    ``t_end`` (times of their first and last sample), ``time`` seconds in all (rows x sample time),
    ``mode`` the label of the mode with the most time among them. ``runs > 1``: a merged row."""

    mode: str
    t_start: float
    t_end: float
    time: float
    runs: int = 1

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


def _dominant(group: Sequence[TimelineRow]) -> str:
    """The mode with the most time in ``group`` (the first of equals)."""
    time: dict[str, float] = {}
    for r in group:
        time[r.mode] = time.get(r.mode, 0.0) + r.time
    return max(time, key=time.__getitem__)


def merge_short_runs(runs: Sequence[TimelineRow], min_run: float) -> tuple[TimelineRow, ...]:
    """A mode timeline for people: runs shorter than ``min_run`` seconds absorbed into their neighbours.

    Noise makes the mode detection flicker where alpha passes a tolerance boundary (a steering
    test passing alpha = 0 flickers between ``1 parking`` and ``2s straight``). Runs of at least
    ``min_run`` s (``time``) are anchors; each cluster of consecutive shorter runs between two anchors

    - joins both anchors into one row when they are in the same mode (flicker between A and B
      inside a longer A stretch becomes part of A);
    - else is a row of its own when the cluster lasts ``min_run`` or more in all;
    - else goes to the anchor whose mode has more time inside the cluster (the preceding on a tie).

    A cluster before the first or after the last anchor goes to it (a row of its own when it lasts
    ``min_run`` or more); without any anchor all runs are one row. Neighbouring rows of the same
    mode are then joined. A merged row's ``mode`` is the mode with the most time inside it, ``runs``
    the number of runs it holds, ``time`` their total. The total time and the span are kept:
    ``sum(r.time)`` and the first start and last end do not change, and the rows stay in order
    and do not overlap. ``min_run = 0`` returns the runs unchanged.

    Example: ``1`` 4 s, ``2s`` 0.1 s, ``1`` 0.05 s, ``2s`` 0.2 s, ``1`` 3 s with ``min_run = 0.5``
    is one row ``1`` of 7.35 s holding 5 runs.
    """
    if not min_run >= 0:
        raise ValueError(f"min_run={min_run!r}: expected a number >= 0 (s)")
    runs = tuple(runs)
    if min_run == 0 or len(runs) < 2:
        return runs
    anchors = [i for i, r in enumerate(runs) if r.time >= min_run]
    groups: list[list[TimelineRow]] = []
    if not anchors:
        groups.append(list(runs))
    else:
        pending = list(runs[:anchors[0]])  # short runs waiting for the next anchor's group
        if sum(r.time for r in pending) >= min_run:
            groups.append(pending)
            pending = []
        join_next = False
        for k, a in enumerate(anchors):
            if join_next:
                groups[-1] += pending + [runs[a]]
            else:
                groups.append(pending + [runs[a]])
            pending, join_next = [], False
            end = anchors[k + 1] if k + 1 < len(anchors) else len(runs)
            cluster = list(runs[a + 1:end])
            if not cluster:
                continue
            if end == len(runs):  # after the last anchor
                if sum(r.time for r in cluster) >= min_run:
                    groups.append(cluster)
                else:
                    groups[-1] += cluster
            elif runs[a].mode == runs[end].mode:
                groups[-1] += cluster
                join_next = True
            elif sum(r.time for r in cluster) >= min_run:
                groups.append(cluster)
            else:
                here = sum(r.time for r in cluster if r.mode == runs[a].mode)
                there = sum(r.time for r in cluster if r.mode == runs[end].mode)
                if there > here:
                    pending = cluster
                else:
                    groups[-1] += cluster
    joined: list[list[TimelineRow]] = []
    for g in groups:
        if joined and _dominant(joined[-1]) == _dominant(g):
            joined[-1] += g
        else:
            joined.append(g)
    return tuple(TimelineRow(_dominant(g), g[0].t_start, g[-1].t_end, sum(r.time for r in g), sum(r.runs for r in g))
                 for g in joined)


def _row_runs(t: np.ndarray, modes: np.ndarray, sample_time: float) -> tuple[TimelineRow, ...]:
    """Every run of the identification's row modes (0: none) as a TimelineRow, unmerged."""
    return tuple(TimelineRow(Mode(int(modes[a])).label if modes[a] else "none", float(t[a]), float(t[b - 1]),
                             (b - a) * sample_time) for a, b in runs(modes))


def _mode_rows(detected: Sequence[ModeRun], sample_time: float) -> tuple[TimelineRow, ...]:
    return tuple(TimelineRow(f"{m.mode.label} {m.mode.name.lower()}", m.t_start, m.t_end,
                             (m.stop - m.start) * sample_time) for m in detected)


@dataclass(frozen=True, eq=False)
class FileCheck:
    """One file: its summary (eq. 9 on the raw angles, labels), the identification's rows, gaps.

    ``row_runs``: every run of the identification's row modes (``timeline`` is them merged as
    ``--json`` lists them); :meth:`mode_rows` and :meth:`timeline_rows` are the printed timelines.
    """

    summary: LogSummary
    rows: LogRows
    timeline: tuple[tuple[str, float, float], ...]
    gaps: tuple[str, ...]
    row_runs: tuple[TimelineRow, ...] = ()

    def mode_rows(self, min_run: float) -> tuple[TimelineRow, ...]:
        """The runs of eq. 9 on the raw angles (every detected run), :func:`merge_short_runs`."""
        detected = self.summary.detected or self.summary.modes
        return merge_short_runs(_mode_rows(detected, self.summary.sample_time), min_run)

    def timeline_rows(self, min_run: float) -> tuple[TimelineRow, ...]:
        """The runs of the identification's row modes, :func:`merge_short_runs`."""
        return merge_short_runs(self.row_runs, min_run)

    def to_dict(self) -> dict[str, Any]:
        out = self.summary.to_dict()
        out.update({
            "gaps": list(self.gaps),
            "mode_timeline": [{"mode": m, "start": a, "end": b} for m, a, b in self.timeline],
            "rows": self.rows.counts.to_dict(),
            "clipped_stop_rows": dict(self.rows.counts.clipped_stop),
            "slip_events": [e.to_dict() for e in self.rows.slip_events],
            "slip_threshold_mps": self.rows.slip_threshold,
        })
        return out


@dataclass(frozen=True, eq=False)
class Preflight:
    """Result of :func:`preflight`."""

    files: tuple[FileCheck, ...]
    excitation: tuple[Excitation, ...]
    ready: bool
    verdict: str
    warnings: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        first = self.files[0].to_dict() if self.files else {}
        return {**first, "files": [f.to_dict() for f in self.files],
                "excitation": {e.name: e.to_dict() for e in self.excitation},
                "ready": self.ready, "verdict": self.verdict, "warnings": list(self.warnings)}


def _timeline(t: np.ndarray, modes: np.ndarray, min_duration: float) -> tuple[tuple[str, float, float], ...]:
    """Runs of the identification's row modes as (label, t_start, t_end); runs shorter than
    ``min_duration`` merged into the preceding one."""
    out: list[list[Any]] = []
    for a, b in runs(modes):
        label = Mode(int(modes[a])).label if modes[a] else "none"
        if out and (out[-1][0] == label or t[b - 1] - t[a] < min_duration):
            out[-1][2] = float(t[b - 1])
        else:
            out.append([label, float(t[a]), float(t[b - 1])])
    return tuple((m, a, b) for m, a, b in out)


def _excitation(rows: Sequence[LogRows], fixed: Mapping[str, float], settings: IdentificationSettings
                ) -> list[Excitation]:
    """How well the kept rows excite each parameter: the rank and variance inflation of the
    identification's first step (:mod:`agvdyn.identification.excitation`) and the relative std of
    an ordinary least-squares trial fit (its estimate step), on the rows' normal equations."""
    names, free, idx_free, p_fixed = columns(fixed, settings.fit.torque_offsets)
    out = {n: Excitation(n, "fixed") for n in PARAMETER_NAMES if n in fixed}
    data = normal_equations([b for r in rows for b in r.blocks], idx_free, p_fixed,
                            offsets=settings.fit.torque_offsets)
    try:
        if data.n_rows <= len(free):
            out.update({n: Excitation(n, "not excited") for n in free if n in PARAMETER_NAMES})
            return [out[n] for n in PARAMETER_NAMES]
        missing = {d.name for d in dependent_parameters(data.A, free, tolerance=settings.fit.rank_tolerance)}
        keep = [n for n in free if n not in missing]
        held = data.holding([free.index(n) for n in missing], np.zeros(len(missing)))
        inflation = variance_inflation(held.A)
        trial = estimate(ExcitationCheck(held, tuple(keep), {}, frozenset(), (), ()), LeastSquares(), settings)
        est = trial.estimator
    finally:
        data.store.close()
    for j, n in enumerate(keep):
        if n not in PARAMETER_NAMES:
            continue
        rel = float(est.std_[j] / abs(est.coef_[j])) if est.coef_[j] != 0 else math.inf
        # as identify: a poorly conditioned parameter counts when the rows determine it (fit.py)
        weak = (inflation[j] > settings.fit.max_inflation and not rel <= COLLINEAR_RELATIVE_STD) \
            or rel > settings.fit.max_relative_std
        out[n] = Excitation(n, "weak" if weak else "ok", float(inflation[j]), rel)
    out.update({n: Excitation(n, "not excited") for n in missing if n in PARAMETER_NAMES})
    return [out[n] for n in PARAMETER_NAMES]


def preflight(logs: Sequence[Any], geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
              settings: IdentificationSettings = IdentificationSettings(), min_duration: float = 0.05,
              rows: Sequence[LogRows] | None = None) -> Preflight:
    """Check logs before identifying: per-file facts, excitation per parameter, verdict.

    ``rows``: the row passes of ``logs`` already made (:func:`agvdyn.identification.row_passes`,
    shared with :func:`~agvdyn.identification.identify` by the report); else made here, once per log."""
    if rows is not None and len(rows) != len(logs):
        raise ValueError(f"rows: expected the row passes of the {len(logs)} logs, got {len(rows)}")
    all_rows = list(rows) if rows is not None else row_passes(logs, geometry, settings)
    files, warnings = [], []
    for log, rows in zip(logs, all_rows):
        files.append(FileCheck(summarize_log(log, geometry, tolerance=settings.rows.mode_tolerance,
                                             min_duration=min_duration),
                               rows, _timeline(log.t, rows.modes, min_duration), rows.cuts,
                               _row_runs(log.t, rows.modes, log.sample_time)))
        c = rows.counts
        if rows.slip_events:
            warnings.append(f"{rows.source}: {len(rows.slip_events)} wheel-slip events, {c.slip:,} rows dropped")
        if sum(c.clipped_stop.values()):
            warnings.append(f"{rows.source}: {sum(c.clipped_stop.values()):,} steering samples clipped to the stops")
        if c.no_mode:
            warnings.append(f"{rows.source}: {c.no_mode:,} rows with the chassis moving in no motion mode (left out)")
        if c.too_short:
            warnings.append(f"{rows.source}: {c.too_short:,} rows in stretches too short to filter (left out)")
    excitation = _excitation(all_rows, fixed, settings)
    lacking = [e for e in excitation if e.status in ("weak", "not excited")]
    if not lacking:
        verdict = f"ready: all {sum(e.status == 'ok' for e in excitation)} free parameters are well excited"
    else:
        missing = sorted({e.excited_by for e in lacking})
        verdict = ("not ready: " + ", ".join(f"{e.name} ({e.status})" for e in lacking) +
                   "; record: " + "; ".join(missing))
    return Preflight(tuple(files), tuple(excitation), not lacking, verdict, tuple(warnings))
