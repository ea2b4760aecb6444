"""The payload tracker with the C++ update (``agvdyn_ff::PayloadTracker`` through :mod:`agvdyn.ffcpp`):
:func:`run_tracker` and :func:`track` as in :mod:`agvdyn.online.tracker` and :func:`agvdyn.online.track`,
the same results (the C++ twin follows the kernels operation by operation; docs/cpp.md). The causal
rows stay Python's (:mod:`agvdyn.online.rows`). ``agvdyn track --engine cpp`` uses :func:`track`.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from agvdyn import ffcpp
from agvdyn.online.rows import TRACKED, OnlineRows
from agvdyn.online.tracker import ChangeEvent, TrackerSettings, TrackerState
from agvdyn.platform import Geometry, Parameters

__all__ = ["run_tracker", "track"]


def run_tracker(rows: OnlineRows, state: TrackerState, settings: TrackerSettings, nominal: np.ndarray,
                source: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[ChangeEvent]]:
    """:func:`agvdyn.online.tracker.run_tracker` with the C++ update: same arguments and results."""
    theta, var, nis, flag, raw = ffcpp.track_rows(rows.kind, rows.phi, rows.z, state, settings, nominal, rows.dt)
    late = rows.lookahead * rows.dt
    found = [ChangeEvent(TRACKED[p], float(rows.t[k] + late), float(rows.t[start] - rows.group_delay), int(sign),
                         float(before), math.sqrt(before_var), float(after), math.sqrt(after_var), source)
             for k, start, p, sign, before, before_var, after, after_var in raw[:settings.max_events]]
    return theta, var, nis, flag, found


def track(logs: Sequence[Any], geometry: Geometry, params: Parameters, *, std: dict[str, float] | None = None,
          settings: TrackerSettings = TrackerSettings()):
    """:func:`agvdyn.online.track` with the C++ update: the same replay (state carried from log to log,
    CUSUMs restarted) and the same :class:`~agvdyn.online.TrackResult`."""
    from agvdyn.online import TrackResult, _log_rows

    if not logs:
        raise ValueError("track: no logs given")
    ffcpp.extension()  # CppEngineUnavailable before any work
    nominal = np.array([getattr(params, name) for name in TRACKED])
    state = TrackerState.initial(params, std or {}, settings)
    parts, events, sources = [], [], []
    for n, log in enumerate(logs):
        source = str(getattr(log, "path", None) or f"<log {n}>")
        rows = _log_rows(log, geometry, params, settings)
        state.g[:] = 0.0
        theta, var, nis, flag, found = run_tracker(rows, state, settings, nominal, source)
        parts.append((rows.t, np.full(rows.n, n), theta, var, nis, flag))
        events += found
        sources.append(source)
    cat = [np.concatenate([p[i] for p in parts]) for i in range(6)]
    return TrackResult(cat[0], cat[1], tuple(sources), cat[2][:, :2], np.sqrt(cat[3][:, :2]), cat[4], cat[5],
                       tuple(events), settings, state.theta[2:].copy(), np.sqrt(state.R), rows.group_delay,
                       rows.lookahead * rows.dt)
