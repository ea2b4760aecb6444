"""Stage 1 of the row pipeline: continuous stretches of a log, each filtered once (sec. 7).

A log is cut only where the recording is not continuous: a time step longer than a few nominal
steps (a dropout) or an angle step no vehicle can make (two recordings joined, an encoder
reset). Each stretch is low-passed and differentiated once, as a whole; odometry (eq. 3), the
slip speed of the redundant rolling constraints and the entries of Theta (eq. 16) are computed
on the filtered signals, and in PARALLEL filtering the entries of Theta and the torques are
low-passed once more together. Segment labels, motion modes, stiction and slip are decided
afterwards, row by row, on these filtered signals: no filter ever starts or ends at a label.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.dynamics import regressor_signals
from agvdyn.identification.settings import Filtering, IdentificationSettings
from agvdyn.odometry import odometry_with_slip
from agvdyn.platform import Geometry
from agvdyn.signals import filtered_derivatives, lowpass, row_max_abs, time_derivative, uniform_sample_time

__all__ = ["Stretch", "stretch_bounds", "filtered_stretch", "log_source", "edge_rows", "min_stretch_rows",
           "torque_lead", "align_torque"]


def log_source(log: Any) -> str:
    return str(getattr(log, "path", None) or "<log>")


@dataclass(frozen=True, eq=False)
class Stretch:
    """One continuous stretch of a log, filtered once; arrays have the stretch's rows first.

    ``rows``: the rows of the log. ``alpha`` (n, 2) filtered steering angles (clipped to the
    stops), ``alpha_dot``, ``alpha_ddot``; ``beta_dot``, ``beta_ddot`` (n, 4); ``chassis_dot``,
    ``chassis_ddot`` (n, 3) by odometry (eq. 3); ``slip`` (n, 4) slip speed per wheel (m/s);
    ``signals`` (n, 21) entries of Theta (:data:`agvdyn.dynamics.REGRESSOR_SIGNALS`) and
    ``torque`` (n, 4) motor torques, both filtered alike in PARALLEL filtering; ``edge`` (n,)
    rows within the filter's transient of either end.
    """

    source: str
    rows: slice
    t: np.ndarray
    dt: float
    alpha: np.ndarray
    alpha_dot: np.ndarray
    alpha_ddot: np.ndarray
    beta_dot: np.ndarray
    beta_ddot: np.ndarray
    chassis_dot: np.ndarray
    chassis_ddot: np.ndarray
    slip: np.ndarray
    signals: np.ndarray
    torque: np.ndarray
    edge: np.ndarray

    @property
    def n(self) -> int:
        return self.t.size

    @property
    def q_dot(self) -> np.ndarray:
        return np.concatenate([self.chassis_dot, self.alpha_dot, self.beta_dot], axis=1)


def torque_lead(log: Any, settings: IdentificationSettings) -> float:
    """Samples by which a log's torques lead its angles: ``settings.torque_lead``, else the sidecar's
    ``torque_lead`` (``agvdyn.simulation`` writes 0.5), else 0."""
    if settings.torque_lead is not None:
        return float(settings.torque_lead)
    sidecar = getattr(log, "sidecar", None)
    value = sidecar.get("torque_lead") if isinstance(sidecar, dict) else None
    if value is None:
        return 0.0
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
        raise ValueError(f"{log_source(log)}: sidecar torque_lead={value!r}: expected a number of samples in [0, 1]")
    return float(value)


def align_torque(torque: np.ndarray, lead: float) -> np.ndarray:
    """Torques at the instants of the angle samples: ``(1 - lead) m[k] + lead m[k - 1]`` (first row kept).

    A zero-order-hold drive applies the torque logged in row k from t_k to t_k + T_s; around t_k
    it acts as the mean of the held values before and after, ``(m[k - 1] + m[k]) / 2`` (lead 0.5).
    """
    if lead == 0 or torque.shape[0] < 2:
        return torque
    out = torque.copy()
    out[1:] = (1.0 - lead) * torque[1:] + lead * torque[:-1]
    return out


def edge_rows(settings: IdentificationSettings, dt: float) -> int:
    """Rows dropped at each end of a stretch: the filter's transient."""
    return int(math.ceil(settings.seconds(settings.edge_guard) / dt))


def min_stretch_rows(settings: IdentificationSettings, dt: float) -> int:
    """Fewest rows a stretch needs: more than the filter's padding and both edges."""
    return max(settings.filter.padlen(dt), 2 * edge_rows(settings, dt)) + 1


def stretch_bounds(t: np.ndarray, alpha: np.ndarray, beta: np.ndarray, settings: IdentificationSettings
                   ) -> tuple[list[tuple[int, int]], list[str]]:
    """Half-open row ranges of the continuous stretches of a log, and why each cut was made."""
    steps = np.diff(t)
    if steps.size == 0:
        return [(0, t.size)], []
    nominal = float(np.median(steps))
    gap = steps > settings.stretch_gap * nominal
    steer = row_max_abs(np.diff(alpha, axis=0)) > settings.steering_jump_rate * nominal
    wheel = row_max_abs(np.diff(beta, axis=0)) > settings.wheel_jump_rate * nominal
    cuts = np.flatnonzero(gap | steer | wheel)
    reasons = []
    for i in cuts:
        what = (f"a dropout of {steps[i]:.4g} s" if gap[i] else
                "a steering angle jump" if steer[i] else "a wheel angle jump")
        reasons.append(f"cut between t = {t[i]:.6g} s and {t[i + 1]:.6g} s: {what}")
    starts = np.concatenate([[0], cuts + 1])
    stops = np.concatenate([cuts + 1, [t.size]])
    return list(zip(starts.tolist(), stops.tolist())), reasons


def filtered_stretch(geometry: Geometry, log: Any, start: int, stop: int, settings: IdentificationSettings
                     ) -> Stretch:
    """Filter, differentiate and evaluate one stretch ``[start, stop)`` of a log once.

    Raises ValueError (naming source and rows) when the stretch is not uniformly sampled or is
    too short for the zero-phase filter.
    """
    source = log_source(log)
    sl = slice(start, stop)
    t = np.asarray(log.t[sl], dtype=float)
    where = f"{source}: rows {start}..{stop - 1} (t = {t[0]:.6g}..{t[-1]:.6g} s)"
    dt = uniform_sample_time(t, rtol=settings.sample_jitter, source=f"{where}: column 't'")
    angles = np.concatenate([log.alpha[sl], log.beta[sl]], axis=1)
    f, f_d, f_dd = filtered_derivatives(angles, dt, settings.filter)
    alpha = np.clip(f[:, :2], -math.pi / 2, math.pi / 2)  # the filter may overshoot the stops
    alpha_dot, alpha_ddot = f_d[:, :2], f_dd[:, :2]
    beta_dot, beta_ddot = f_d[:, 2:], f_dd[:, 2:]
    chassis_dot, slip = odometry_with_slip(geometry, alpha, alpha_dot, beta_dot)
    chassis_ddot = time_derivative(chassis_dot, dt)
    q_dot = np.concatenate([chassis_dot, alpha_dot, beta_dot], axis=1)
    q_ddot = np.concatenate([chassis_ddot, alpha_ddot, beta_ddot], axis=1)
    signals = regressor_signals(q_dot, q_ddot, settings.epsilon)
    torque = align_torque(np.asarray(log.torque[sl], dtype=float), torque_lead(log, settings))
    if settings.filtering is Filtering.PARALLEL:
        both = lowpass(np.concatenate([signals, torque], axis=1), dt, settings.filter)
        signals, torque = both[:, :-4], both[:, -4:]
    else:
        torque = lowpass(torque, dt, settings.filter)
    n = t.size
    k = edge_rows(settings, dt)
    edge = np.zeros(n, dtype=bool)
    edge[:k] = True
    edge[max(n - k, 0):] = True
    return Stretch(source, sl, t, dt, alpha, alpha_dot, alpha_ddot, beta_dot, beta_ddot, chassis_dot,
                   chassis_ddot, slip, signals, torque, edge)
