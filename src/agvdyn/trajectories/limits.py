"""Limits a planned trajectory must respect, and the floor space it occupies (sec. 6.2; :class:`FloorSpace`
and :func:`floor_space` are defined with the trajectory in :mod:`.segments`, re-exported here)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agvdyn.platform import PAPER_PARAMETERS, Parameters
from agvdyn.trajectories.errors import LimitError, TrajectoryError
from agvdyn.trajectories.segments import FloorSpace, Trajectory, floor_space  # noqa: F401  (re-exported)

__all__ = ["Limits", "LimitReport", "limit_report", "check_limits", "FloorSpace", "floor_space"]


@dataclass(frozen=True)
class Limits:
    """Limits a planned trajectory must respect (checked by :func:`check_limits`).

    Velocities on the wheel side (``wheel_speed``, rad/s), chassis speed (m/s), yaw rate (rad/s),
    steering rate (rad/s) and their accelerations; ``motor_torque`` is the motor's peak torque
    (N m) and ``feedforward_share`` the share of it the feed-forward may use (the rest is left
    to the feedback).
    """

    steering_rate: float = 2.0
    steering_acceleration: float = 20.0
    speed: float = 1.5
    acceleration: float = 1.5
    yaw_rate: float = 1.5
    yaw_acceleration: float = 3.0
    wheel_speed: float = 20.0
    motor_torque: float = 6.0
    feedforward_share: float = 0.8

    def __post_init__(self) -> None:
        for f in self.__dataclass_fields__:
            if not getattr(self, f) > 0:
                raise TrajectoryError(f"limit {f}={getattr(self, f)!r}: expected > 0")


@dataclass(frozen=True)
class LimitReport:
    """Peak values of a planned trajectory next to the limits (one entry per limit name)."""

    peaks: dict[str, float]
    limits: dict[str, float]
    worst: dict[str, tuple[str, float]]  # limit -> (segment, time)

    @property
    def ok(self) -> bool:
        return all(self.peaks[k] <= self.limits[k] for k in self.peaks)


def limit_report(traj: Trajectory, params: Parameters = PAPER_PARAMETERS, limits: Limits = Limits(), *,
                 motion: tuple[np.ndarray, np.ndarray] | None = None, torques: np.ndarray | None = None
                 ) -> LimitReport:
    """Peaks of the planned velocities, accelerations and feed-forward torques (eq. 21 with ``params``).

    ``motion`` = ``traj.joint_motion()`` and ``torques`` = ``traj.feedforward(params)`` when already computed.
    """
    qd, qdd = traj.joint_motion() if motion is None else motion
    u = traj.feedforward(params) if torques is None else torques
    values = {
        "steering_rate": _largest_magnitude(qd[:, 3:5]),
        "steering_acceleration": _largest_magnitude(qdd[:, 3:5]),
        "speed": np.hypot(qd[:, 0], qd[:, 1]),
        "acceleration": np.hypot(qdd[:, 0], qdd[:, 1]),
        "yaw_rate": np.abs(qd[:, 2]),
        "yaw_acceleration": np.abs(qdd[:, 2]),
        "wheel_speed": _largest_magnitude(qd[:, 5:]),
        "motor_torque": _largest_magnitude(u),
    }
    lim = {k: getattr(limits, k) for k in values}
    lim["motor_torque"] = limits.motor_torque * limits.feedforward_share
    peaks, worst = {}, {}
    for k, v in values.items():
        i = int(np.argmax(v))
        peaks[k] = float(v[i])
        worst[k] = (str(traj.segment[i]), float(traj.t[i]))
    return LimitReport(peaks, lim, worst)


def _largest_magnitude(x: np.ndarray) -> np.ndarray:
    """max |x| along the rows ``(N,)`` of x ``(N, k)``, column by column (a reduction along a short
    axis is several times slower)."""
    out = np.abs(x[:, 0])
    for j in range(1, x.shape[1]):
        np.maximum(out, np.abs(x[:, j]), out=out)
    return out


def check_limits(traj: Trajectory, params: Parameters = PAPER_PARAMETERS, limits: Limits = Limits(), *,
                 motion: tuple[np.ndarray, np.ndarray] | None = None, torques: np.ndarray | None = None
                 ) -> LimitReport:
    """Raise :class:`LimitError` naming the first broken limit, its segment, time and value; else the report."""
    report = limit_report(traj, params, limits, motion=motion, torques=torques)
    for k in report.peaks:
        if report.peaks[k] > report.limits[k]:
            seg, t = report.worst[k]
            raise LimitError(
                f"trajectory {traj.name!r} breaks the {k} limit in segment {seg!r} at t = {t:.3f} s: "
                f"{report.peaks[k]:.4g} > {report.limits[k]:.4g}"
            )
    return report
