"""The payload tracker with the C++ update (``agvdyn_ff::PayloadTracker`` through :mod:`agvdyn.ffcpp`):
:func:`run_tracker` and :func:`track` as in :mod:`agvdyn.online.tracker` and :func:`agvdyn.online.track`,
the same results (the C++ twin follows the kernels operation by operation; docs/cpp.md). The causal
rows stay Python's (:mod:`agvdyn.online.rows`). ``agvdyn track --engine cpp`` uses :func:`track`.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from agvdyn import ffcpp
from agvdyn.model_spec import ModelParameters
from agvdyn.online.rows import OnlineRows
from agvdyn.online.tracker import TrackerRun, TrackerSettings, TrackerState, change_events, check_rows
from agvdyn.platform import Geometry, Parameters

__all__ = ["run_tracker", "track"]


def run_tracker(rows: OnlineRows, state: TrackerState, settings: TrackerSettings, nominal: np.ndarray,
                source: str = "") -> TrackerRun:
    """:func:`agvdyn.online.tracker.run_tracker` with the C++ update: same arguments and results."""
    check_rows(rows, state, settings)
    theta, var, nis, flag, raw, offset = ffcpp.track_rows(rows.kind, rows.phi, rows.z, state, settings, nominal,
                                                          rows.dt)
    return TrackerRun(theta, var, nis, flag, change_events(rows, raw[:settings.max_events], source), offset)


def track(logs: Sequence[Any], geometry: Geometry, params: Parameters | ModelParameters, *,
          std: dict[str, float] | None = None, settings: TrackerSettings = TrackerSettings()):
    """:func:`agvdyn.online.track` with the C++ update: the same replay (state carried from log to log,
    CUSUMs restarted) and the same :class:`~agvdyn.online.TrackResult`."""
    from agvdyn.online import track as replay

    ffcpp.extension()  # CppEngineUnavailable before any work
    return replay(logs, geometry, params, std=std, settings=settings, run=run_tracker)
