"""Online payload tracking (issue 31): recursive m_ch and C_ch with change detection, a stage above
the identification (it holds the identified parameters and uses the identification's row rules).

::

    rows      causal rows of eq. (19): forward-only filters, the chassis rows of each motion mode
    tracker   the tracker: Kalman filter with random walk, information gating, CUSUM change
              detection with covariance reset (the algorithm the C++ twin follows)
    _kernels  its compiled update

Entry point :func:`track` replays logs through it and returns a :class:`TrackResult`
(docs/online.md; ``agvdyn track`` on the command line).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from agvdyn.online.rows import ROW_KINDS, TRACKED, OnlineRows, causal_rows
from agvdyn.online.tracker import ChangeEvent, TrackerSettings, TrackerState, run_tracker
from agvdyn.platform import Geometry, Parameters

__all__ = ["track", "TrackResult", "TrackerSettings", "ChangeEvent", "OnlineRows", "causal_rows", "TRACKED"]


@dataclass(frozen=True, eq=False)
class TrackResult:
    """Per sample of the logs (concatenated): ``t`` (N,) s, ``source`` (N,) index into ``sources``,
    ``estimate`` (N, 2) and ``std`` (N, 2) of (m_ch, C_ch), ``nis`` (N,) (NaN without a row), ``event``
    (N,) flags (1: m_ch, 2: C_ch); ``events`` the detected changes; ``settings``; ``bias`` (6,) the
    final row biases of the kinds of :data:`~agvdyn.online.rows.ROW_KINDS` and ``noise_std`` (3,) the
    residual stds of the x_ch, y_ch, gamma_ch rows."""

    t: np.ndarray
    source: np.ndarray
    sources: tuple[str, ...]
    estimate: np.ndarray
    std: np.ndarray
    nis: np.ndarray
    event: np.ndarray
    events: tuple[ChangeEvent, ...]
    settings: TrackerSettings
    bias: np.ndarray
    noise_std: np.ndarray
    group_delay: float
    latency: float

    def final(self) -> dict[str, dict[str, float]]:
        """The last estimates with their std."""
        return {name: {"value": float(self.estimate[-1, i]), "std": float(self.std[-1, i])}
                for i, name in enumerate(TRACKED)}

    def table(self, rate: float | None = 10.0) -> dict[str, np.ndarray]:
        """Columns ``t, m_ch, m_ch_std, C_ch, C_ch_std, nis, event`` decimated to ``rate`` Hz (None: every
        sample): the last sample of each interval, ``nis`` its mean over the interval, ``event`` the
        union of its flags (no event is lost)."""
        n = self.t.size
        step = 1 if rate is None else max(1, int(round(1.0 / (rate * self._dt()))))
        ends = np.minimum(np.arange(step - 1, n + step - 1, step), n - 1)
        starts = np.concatenate([[0], ends[:-1] + 1])
        nis = np.where(np.isnan(self.nis), 0.0, self.nis)
        cnt = np.add.reduceat((~np.isnan(self.nis)).astype(float), starts)
        with np.errstate(invalid="ignore", divide="ignore"):
            nis_mean = np.add.reduceat(nis, starts) / cnt
        return {"t": self.t[ends], "m_ch": self.estimate[ends, 0], "m_ch_std": self.std[ends, 0],
                "C_ch": self.estimate[ends, 1], "C_ch_std": self.std[ends, 1], "nis": nis_mean,
                "event": np.bitwise_or.reduceat(self.event, starts)}

    def _dt(self) -> float:
        return float(np.median(np.diff(self.t))) if self.t.size > 1 else 1.0

    def value_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Estimate and std (2,) at the last sample at or before ``t``."""
        i = max(int(np.searchsorted(self.t, t, side="right")) - 1, 0)
        return self.estimate[i], self.std[i]

    def to_dict(self) -> dict[str, Any]:
        """JSON summary: final estimates, events, row biases and noise, delays, settings."""
        return {"final": self.final(), "events": [e.to_dict() for e in self.events],
                "row_bias": dict(zip(ROW_KINDS[1:], self.bias.tolist())),
                "row_noise_std": dict(zip(("x_ch", "y_ch", "gamma_ch"), self.noise_std.tolist())),
                "group_delay": self.group_delay, "latency": self.latency, "sources": list(self.sources),
                "settings": {k: v for k, v in self.settings.__dict__.items() if k != "rules"}}


def _log_rows(log: Any, geometry: Geometry, params: Parameters, settings: TrackerSettings) -> OnlineRows:
    from agvdyn.io.log import sidecar_value

    lead = sidecar_value(log, "torque_lead")
    lead = settings.rules.torque_lead if settings.rules.torque_lead is not None else float(lead or 0.0)
    return causal_rows(log.t, log.alpha, log.beta, log.torque, geometry, params, rules=settings.rules,
                       torque_lead=lead, slip_threshold=settings.slip_threshold)


def track(logs: Sequence[Any], geometry: Geometry, params: Parameters, *, std: dict[str, float] | None = None,
          settings: TrackerSettings = TrackerSettings(), run=run_tracker) -> TrackResult:
    """Replay loaded logs (:func:`agvdyn.io.load_log`) in order through the payload tracker.

    ``params``: the identified parameters (every one but m_ch and C_ch held); ``std``: their stds
    (the initial uncertainty of m_ch and C_ch, at least ``settings.initial_std`` of the values). The
    state carries over from one log to the next (the same vehicle, one shift); the CUSUMs restart.
    ``run``: the update over one log's rows (:func:`agvdyn.online.tracker.run_tracker`, or the C++
    twin's :func:`agvdyn.online.cpp.run_tracker`).
    """
    if not logs:
        raise ValueError("track: no logs given")
    nominal = np.array([getattr(params, name) for name in TRACKED])
    state = TrackerState.initial(params, std or {}, settings)
    parts, events, sources = [], [], []
    for n, log in enumerate(logs):
        source = str(getattr(log, "path", None) or f"<log {n}>")
        rows = _log_rows(log, geometry, params, settings)
        state.g[:] = 0.0
        theta, var, nis, flag, found = run(rows, state, settings, nominal, source)
        parts.append((rows.t, np.full(rows.n, n), theta, var, nis, flag))
        events += found
        sources.append(source)
    cat = [np.concatenate([p[i] for p in parts]) for i in range(6)]
    return TrackResult(cat[0], cat[1], tuple(sources), cat[2][:, :2], np.sqrt(cat[3][:, :2]), cat[4], cat[5],
                       tuple(events), settings, state.theta[2:].copy(), np.sqrt(state.R), rows.group_delay,
                       rows.lookahead * rows.dt)
