"""What a log holds: duration, rate, segments and the motion modes over time (``agvdyn inspect``)."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from agvdyn.io.log import Log, SegmentRun
from agvdyn.kinematics import MODE_TOLERANCE, Mode, detect_mode
from agvdyn.platform import Geometry


@dataclass(frozen=True)
class ModeRun:
    """A contiguous run of rows ``start:stop`` detected in one motion mode (eq. 9)."""

    mode: Mode
    start: int
    stop: int
    t_start: float
    t_end: float

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


@dataclass(frozen=True)
class LogSummary:
    """Facts about a log: size, timing, segments and motion modes over time."""

    path: str | None
    n_samples: int
    t_start: float
    t_end: float
    sample_time: float
    segments: tuple[SegmentRun, ...]
    modes: tuple[ModeRun, ...]
    mode_time: dict[str, float]
    tolerance: float
    notes: tuple[str, ...]
    platform: dict[str, Any]
    min_duration: float = 0.0
    n_detected_runs: int = 0
    detected: tuple[ModeRun, ...] = ()  # every run before merging (``modes`` with min_duration = 0)

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start

    @property
    def rate(self) -> float:
        return 1.0 / self.sample_time

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path, "samples": self.n_samples, "t_start": self.t_start, "t_end": self.t_end,
            "duration": self.duration, "sample_time": self.sample_time, "rate": self.rate,
            "segments": [{"name": s.name, "start": s.t_start, "end": s.t_end, "duration": s.duration, "rows": [s.start, s.stop]}
                         for s in self.segments],
            "modes": [_run_dict(m) for m in self.modes],
            # every detected run, none merged (``modes`` merges those under ``min_duration``)
            "detected_modes": [_run_dict(m) for m in (self.detected or self.modes)],
            "mode_time": self.mode_time, "mode_tolerance": self.tolerance,
            "min_duration": self.min_duration, "detected_runs": self.n_detected_runs, "notes": list(self.notes),
            "platform": self.platform,
        }


def _run_dict(m: ModeRun) -> dict[str, Any]:
    return {"mode": m.mode.label, "name": m.mode.name.lower(), "start": m.t_start, "end": m.t_end,
            "duration": m.duration, "rows": [m.start, m.stop]}


def mode_runs(geometry: Geometry, log: Log, tolerance: float = MODE_TOLERANCE) -> tuple[ModeRun, ...]:
    """Contiguous runs of the motion mode detected from ``alpha`` (eq. 9, :func:`detect_mode`)."""
    modes = detect_mode(geometry, log.alpha, tolerance=tolerance)
    change = np.flatnonzero(modes[1:] != modes[:-1]) + 1
    starts = np.concatenate([[0], change])
    stops = np.concatenate([change, [len(modes)]])
    t = log.t
    return tuple(ModeRun(Mode(int(modes[a])), int(a), int(b), float(t[a]), float(t[b - 1])) for a, b in zip(starts, stops))


def merged_runs(runs: tuple[ModeRun, ...], sample_time: float, min_duration: float) -> tuple[ModeRun, ...]:
    """Runs with those shorter than ``min_duration`` (rows x sample time) merged into the preceding run.

    Noise makes the detection flicker where alpha passes a tolerance boundary; merging keeps the
    overview readable. The first run is never merged away; neighbours of equal mode are joined.
    """
    out: list[ModeRun] = []
    for run in runs:
        short = (run.stop - run.start) * sample_time < min_duration
        if out and (short or out[-1].mode == run.mode):
            out[-1] = replace(out[-1], stop=run.stop, t_end=run.t_end)
        else:
            out.append(run)
    return tuple(out)


def summarize_log(log: Log, geometry: Geometry, *, tolerance: float = MODE_TOLERANCE, min_duration: float = 0.0) -> LogSummary:
    """Summary of a log for people: timing, segments, detected modes and the time spent in each.

    The time of a mode counts one sample time per row detected in it (before any merging).
    With ``min_duration > 0`` the listed runs are :func:`merged_runs`.
    """
    if not min_duration >= 0:
        raise ValueError(f"min_duration={min_duration!r}: expected a number >= 0 (s)")
    detected = mode_runs(geometry, log, tolerance)
    runs = merged_runs(detected, log.sample_time, min_duration) if min_duration > 0 else detected
    mode_time: dict[str, float] = {}
    for run in detected:
        key = run.mode.label
        mode_time[key] = mode_time.get(key, 0.0) + (run.stop - run.start) * log.sample_time
    conv = log.sidecar.get("conversion", {}) if isinstance(log.sidecar, dict) else {}
    notes = tuple(str(n) for n in conv.get("notes", []) or [])
    if conv.get("method") and conv.get("rate"):
        notes = (f"resampled at {conv['rate']:g} Hz: {conv['method']}",) + notes
    return LogSummary(
        str(log.path) if log.path else None, log.n_samples, float(log.t[0]), float(log.t[-1]), log.sample_time,
        log.segment_runs(), runs, mode_time, tolerance, notes, geometry.to_dict(), min_duration, len(detected),
        detected,
    )
