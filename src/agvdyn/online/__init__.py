"""Online payload tracking (issue 31): recursive m_ch and C_ch (and the centre-of-mass offset y_c when
asked: ``TrackerSettings(com_offset=True)``) with change detection, a stage above the identification
(it holds the identified parameters and uses the identification's row rules).

::

    rows      causal rows of eq. (19): forward-only filters, the chassis rows of each motion mode
    tracker   the tracker: Kalman filter with random walk, information gating, CUSUM change
              detection with covariance reset (the algorithm the C++ twin follows)
    _kernels  its compiled update

Entry point :func:`track` replays logs through it and returns a :class:`TrackResult`
(docs/online.md; ``agvdyn track`` on the command line).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np

from agvdyn.model_spec import CENTRE_NAMES, ModelParameters
from agvdyn.online import _kernels as kern
from agvdyn.online.rows import BIAS_KINDS, TRACKED, OnlineRows, causal_rows
from agvdyn.online.tracker import ChangeEvent, TrackerRun, TrackerSettings, TrackerState, run_tracker
from agvdyn.platform import Geometry, Parameters

__all__ = ["track", "TrackResult", "TrackerSettings", "ChangeEvent", "OnlineRows", "causal_rows", "TRACKED",
           "NOISE_CLASSES"]

#: The tracker's noise classes (``TrackResult.noise_std``): x_ch rows of straight motion, y_ch, gamma_ch,
#: x_ch rows of car-like motion (their yaw column misfits where the tyres scrub in turns).
NOISE_CLASSES = ("x_ch", "y_ch", "gamma_ch", "x_ch car-like")


@dataclass(frozen=True, eq=False)
class TrackResult:
    """Per sample of the logs (concatenated): ``t`` (N,) s, ``source`` (N,) index into ``sources``,
    ``estimate`` (N, P) and ``std`` (N, P) of :attr:`names` (m_ch, C_ch; with the centre-of-mass offset
    also x_c, y_c: x_c NaN with an infinite std, not identifiable; y_c's std by the delta method, inf until
    a car-like row informs it), ``nis`` (N,) (NaN without a row), ``event`` (N,) flags (1: m_ch, 2: C_ch);
    ``events`` the detected changes; ``settings``; ``bias`` (6,) the final row biases of the kinds of
    :data:`~agvdyn.online.rows.BIAS_KINDS` and ``noise_std`` (4,) the residual stds of the noise classes
    :data:`NOISE_CLASSES` (x_ch rows of straight motion, y_ch, gamma_ch, x_ch rows of car-like motion)."""

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

    @property
    def names(self) -> tuple[str, ...]:
        """The columns of ``estimate`` and ``std``: m_ch, C_ch (+ x_c, y_c with the centre-of-mass offset)."""
        return TRACKED + (CENTRE_NAMES if self.estimate.shape[1] > len(TRACKED) else ())

    def final(self) -> dict[str, dict[str, float]]:
        """The last estimates with their std (x_c: NaN, inf)."""
        return {name: {"value": float(self.estimate[-1, i]), "std": float(self.std[-1, i])}
                for i, name in enumerate(self.names)}

    def table(self, rate: float | None = 10.0) -> dict[str, np.ndarray]:
        """Columns ``t, m_ch, m_ch_std, C_ch, C_ch_std, [x_c, x_c_std, y_c, y_c_std], nis, event`` decimated to
        ``rate`` Hz (None: every sample): the last sample of each interval, ``nis`` its mean over the
        interval, ``event`` the union of its flags (no event is lost)."""
        n = self.t.size
        step = 1 if rate is None else max(1, int(round(1.0 / (rate * self._dt()))))
        ends = np.minimum(np.arange(step - 1, n + step - 1, step), n - 1)
        starts = np.concatenate([[0], ends[:-1] + 1])
        nis = np.where(np.isnan(self.nis), 0.0, self.nis)
        cnt = np.add.reduceat((~np.isnan(self.nis)).astype(float), starts)
        with np.errstate(invalid="ignore", divide="ignore"):
            nis_mean = np.add.reduceat(nis, starts) / cnt
        out = {"t": self.t[ends]}
        for i, name in enumerate(self.names):
            out[name], out[f"{name}_std"] = self.estimate[ends, i], self.std[ends, i]
        return {**out, "nis": nis_mean, "event": np.bitwise_or.reduceat(self.event, starts)}

    def _dt(self) -> float:
        return float(np.median(np.diff(self.t))) if self.t.size > 1 else 1.0

    def value_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Estimate and std (P,) at the last sample at or before ``t``."""
        i = max(int(np.searchsorted(self.t, t, side="right")) - 1, 0)
        return self.estimate[i], self.std[i]

    def to_dict(self) -> dict[str, Any]:
        """JSON summary: final estimates, events, row biases and noise, delays, settings. JSON has no
        infinity: x_c and an uninformed y_c are ``value``/``std`` null (NaN, inf) with ``identified: false``."""
        final: dict[str, Any] = self.final()
        for name in CENTRE_NAMES if CENTRE_NAMES[0] in final else ():
            value, std = final[name]["value"], final[name]["std"]
            final[name] = {"value": value if math.isfinite(value) else None,
                           "std": std if math.isfinite(std) else None, "identified": math.isfinite(std)}
        return {"final": final, "events": [e.to_dict() for e in self.events],
                "row_bias": dict(zip(BIAS_KINDS, self.bias.tolist())),
                "row_noise_std": dict(zip(NOISE_CLASSES, self.noise_std.tolist())),
                "group_delay": self.group_delay, "latency": self.latency, "sources": list(self.sources),
                "settings": {k: v for k, v in self.settings.__dict__.items() if k != "rules"}}


def _log_rows(log: Any, geometry: Geometry, params: Parameters, settings: TrackerSettings) -> OnlineRows:
    from agvdyn.io.log import sidecar_value

    lead = sidecar_value(log, "torque_lead")
    lead = settings.rules.torque_lead if settings.rules.torque_lead is not None else float(lead or 0.0)
    return causal_rows(log.t, log.alpha, log.beta, log.torque, geometry, params, rules=settings.rules,
                       torque_lead=lead, slip_threshold=settings.slip_threshold, com_offset=settings.com_offset)


def _reported(run: TrackerRun, settings: TrackerSettings) -> tuple[np.ndarray, np.ndarray]:
    """Estimates and stds (N, P) of the reported parameters from a run's states (x_c: NaN, inf)."""
    estimate, std = run.theta[:, :2], np.sqrt(run.var[:, :2])
    if not settings.com_offset:
        return estimate, std
    n = estimate.shape[0]
    return (np.column_stack([estimate, np.full(n, np.nan), run.offset[:, 0]]),
            np.column_stack([std, np.full(n, np.inf), run.offset[:, 1]]))


def track(logs: Sequence[Any], geometry: Geometry, params: Parameters | ModelParameters, *,
          std: dict[str, float] | None = None, settings: TrackerSettings = TrackerSettings(),
          run=run_tracker) -> TrackResult:
    """Replay loaded logs (:func:`agvdyn.io.load_log`) in order through the payload tracker.

    ``params``: the identified parameters (every one but m_ch and C_ch held), or a
    :class:`~agvdyn.model_spec.ModelParameters` whose model has the centre-of-mass offset (its y_c is
    the start and ``settings.com_offset`` is then implied; the other extensions are not applied by
    the tracker's rows); ``std``: their stds (the initial uncertainty of m_ch and C_ch, at least
    ``settings.initial_std`` of the values; of y_c, see :meth:`TrackerState.initial`). The state
    carries over from one log to the next (the same vehicle, one shift); the CUSUMs restart.
    ``run``: the update over one log's rows (:func:`agvdyn.online.tracker.run_tracker`, or the C++
    twin's :func:`agvdyn.online.cpp.run_tracker`).
    """
    if not logs:
        raise ValueError("track: no logs given")
    y_c = 0.0
    if isinstance(params, ModelParameters):
        if params.spec.com_offset and not settings.com_offset:
            settings = replace(settings, com_offset=True)
        y_c, params = params.value("y_c"), params.parameters
    nominal = np.array([getattr(params, name) for name in TRACKED])
    state = TrackerState.initial(params, std or {}, settings, y_c)
    parts, events, sources = [], [], []
    for n, log in enumerate(logs):
        source = str(getattr(log, "path", None) or f"<log {n}>")
        rows = _log_rows(log, geometry, params, settings)
        state.g[:] = 0.0
        out = run(rows, state, settings, nominal, source)
        parts.append((rows.t, np.full(rows.n, n), *_reported(out, settings), out.nis, out.event))
        events += out.events
        sources.append(source)
    cat = [np.concatenate([p[i] for p in parts]) for i in range(6)]
    return TrackResult(cat[0], cat[1], tuple(sources), cat[2], cat[3], cat[4], cat[5], tuple(events), settings,
                       state.theta[2:kern.NS].copy(), np.sqrt(state.R), rows.group_delay, rows.lookahead * rows.dt)
