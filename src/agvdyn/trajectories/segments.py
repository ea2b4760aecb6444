"""Segments and trajectories: planned motions sampled at ``T_s``, and their building blocks
(alignment at rest, Fourier segments).

A :class:`Trajectory` is a tuple of :class:`Segment` objects sampled at ``T_s``. Each segment
has one motion mode k and carries the generalized coordinates ``s_k`` of eq. (10)-(13) with
their first two time derivatives, and the steering angles ``alpha`` of every sample, so that
``agvdyn.kinematics.joint_motion`` gives ``q_dot, q_ddot`` (eq. 4, 20) and
``agvdyn.dynamics.feedforward_torques`` the motor torques of eq. (21).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from agvdyn.dynamics import feedforward_torques, generalized_forces
from agvdyn.kinematics import (
    Mode,
    check_mode,
    joint_motion,
    kinematic_model,
    max_virtual_angle,
    nominal_steering,
    steering_from_virtual,
)
from agvdyn.platform import PROTOTYPE, SAMPLE_TIME, Geometry, Parameters
from agvdyn.segments_vocabulary import SEGMENTS
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.fourier import FourierSeries

__all__ = ["CONTINUITY_TOLERANCE", "SEGMENT_NAMES", "Segment", "Trajectory", "FloorSpace", "floor_space",
           "pose_from_velocities", "alignment", "fourier_segment"]

#: Largest jump of the steering angles (rad) allowed between the end of a segment and the next one.
CONTINUITY_TOLERANCE = 1e-3
#: Segment names of PLATFORM.md (the ``segment`` column of a log): :data:`agvdyn.segments_vocabulary.SEGMENTS`.
SEGMENT_NAMES = SEGMENTS


# --- segments and trajectories --------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Segment:
    """One phase of a planned motion in one motion mode, sampled at ``sample_time``.

    ``t`` starts at 0; ``alpha`` is ``(N, 2)``; ``s``, ``s_dot``, ``s_ddot`` are ``(N, n_k)`` in the
    coordinates of ``mode.coordinates``.

    Wheels lifted off the ground (the single-axis experiment of sec. 7, segment ``lifted_wheel``):
    ``wheel_rates`` ``(N, 2, 4)`` holds the planned wheel rates and accelerations (beta_dot,
    beta_ddot, wheel order fl, rl, fr, rr); the chassis stands on jacks, the steering at rest
    (mode 1 with constant ``alpha``), and the wheels turn freely.
    """

    name: str
    mode: Mode
    t: np.ndarray
    alpha: np.ndarray
    s: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray
    wheel_rates: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.name not in SEGMENT_NAMES:
            raise TrajectoryError(f"segment name {self.name!r}: expected one of {list(SEGMENT_NAMES)}")
        object.__setattr__(self, "mode", Mode.from_label(self.mode))
        n = len(self.t)
        if n < 2:
            raise TrajectoryError(f"segment {self.name!r}: {n} samples, expected at least 2")
        for key, width in (("alpha", 2), ("s", self.mode.dof), ("s_dot", self.mode.dof), ("s_ddot", self.mode.dof)):
            arr = np.asarray(getattr(self, key), dtype=float).reshape(n, -1)
            if arr.shape != (n, width) or not np.isfinite(arr).all():
                raise TrajectoryError(f"segment {self.name!r}: {key} of shape {arr.shape}: expected finite ({n}, {width})")
            arr.setflags(write=False)
            object.__setattr__(self, key, arr)
        if self.wheel_rates is not None:
            w = np.asarray(self.wheel_rates, dtype=float)
            if w.shape != (n, 2, 4) or not np.isfinite(w).all():
                raise TrajectoryError(f"segment {self.name!r}: wheel_rates of shape {w.shape}: expected finite ({n}, 2, 4)")
            if self.mode is not Mode.PARKING or np.any(self.s_dot != 0) or np.any(self.s_ddot != 0):
                raise TrajectoryError(f"segment {self.name!r}: lifted wheels need the steering at rest (mode 1, "
                                      "s_dot = s_ddot = 0)")
            w.setflags(write=False)
            object.__setattr__(self, "wheel_rates", w)

    @property
    def lifted(self) -> bool:
        """The wheels turn off the ground (``wheel_rates`` given)."""
        return self.wheel_rates is not None

    def joint_motion(self, geom: Geometry) -> tuple[np.ndarray, np.ndarray]:
        """Planned ``(q_dot, q_ddot)`` ``(N, 9)``: eq. (4) and (20), or the free wheels when lifted."""
        if self.mode is Mode.CAR_LIKE:
            return joint_motion(geom, self.mode, self.alpha, self.s_dot, self.s_ddot)
        if not self.lifted:  # H_k constant (dH_k/dt = 0): q_dot = H_k s_dot, q_ddot = H_k s_ddot
            H = kinematic_model(geom, self.mode, self.alpha)[0]
            return _times_columns(self.s_dot, H), _times_columns(self.s_ddot, H)
        qd, qdd = np.zeros((self.n_samples, 9)), np.zeros((self.n_samples, 9))
        qd[:, 5:], qdd[:, 5:] = self.wheel_rates[:, 0], self.wheel_rates[:, 1]
        return qd, qdd

    def feedforward(self, geom: Geometry, params: Parameters,
                    motion: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Motor torques ``(N, 4)``: eq. (21), or, lifted, the wheel rows of eq. (16)-(17) alone
        (``i_G M = B_w beta_ddot + d_vw beta_dot + d_cw tanh(beta_dot / epsilon)``).
        ``motion``: :meth:`joint_motion` when already computed."""
        if not self.lifted:
            return feedforward_torques(geom, params, self.mode, self.alpha, self.s_dot, self.s_ddot, motion=motion)
        qd, qdd = self.joint_motion(geom) if motion is None else motion
        return generalized_forces(qd, qdd, params)[:, 5:] / geom.i_G

    @property
    def n_samples(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A planned motion: segments one after the other on one time grid of step ``sample_time``.

    Attributes (per sample, leading axis N): ``t``, ``alpha`` (N, 2), ``mode`` (N,) int,
    ``segment`` (N,) names, ``s``, ``s_dot``, ``s_ddot`` (N, 2) (NaN-padded for one-coordinate
    modes); per segment: ``segments[i].s`` etc. with exactly ``mode.dof`` columns.
    """

    segments: tuple[Segment, ...]
    geometry: Geometry = PROTOTYPE
    sample_time: float = SAMPLE_TIME
    name: str = "trajectory"

    def __post_init__(self) -> None:
        if not self.segments:
            raise TrajectoryError("a trajectory needs at least one segment")
        object.__setattr__(self, "segments", tuple(self.segments))
        lifted = [seg.lifted for seg in self.segments]
        if any(lifted) and not all(lifted):
            raise TrajectoryError(f"trajectory {self.name!r}: segments {[s.name for s in self.segments]} mix lifted "
                                  "wheels and ground contact: expected a lifted-wheel experiment on its own")
        for i, seg in enumerate(self.segments):
            try:
                check_mode(self.geometry, seg.mode, seg.alpha)
            except ValueError as exc:
                raise TrajectoryError(f"segment {i} ({seg.name!r}): {exc}") from exc
            if i and np.max(np.abs(seg.alpha[0] - self.segments[i - 1].alpha[-1])) > CONTINUITY_TOLERANCE:
                end = self.segments[i - 1].alpha[-1]
                raise TrajectoryError(
                    f"segment {i} ({seg.name!r}) starts at alpha = ({seg.alpha[0, 0]:.6g}, {seg.alpha[0, 1]:.6g}) but "
                    f"segment {i - 1} ends at ({end[0]:.6g}, {end[1]:.6g}): insert an alignment"
                )

    @cached_property
    def bounds(self) -> np.ndarray:
        """Start row of each segment and the total number of rows ``(n_segments + 1,)``."""
        return np.concatenate([[0], np.cumsum([s.n_samples for s in self.segments])])

    @property
    def n_samples(self) -> int:
        return int(self.bounds[-1])

    @cached_property
    def t(self) -> np.ndarray:
        return np.arange(self.n_samples) * self.sample_time

    @property
    def duration(self) -> float:
        return self.n_samples * self.sample_time

    @cached_property
    def alpha(self) -> np.ndarray:
        return np.concatenate([s.alpha for s in self.segments])

    @cached_property
    def mode(self) -> np.ndarray:
        return np.concatenate([np.full(s.n_samples, int(s.mode), dtype=np.int8) for s in self.segments])

    @cached_property
    def segment(self) -> np.ndarray:
        return np.concatenate([np.full(s.n_samples, s.name, dtype=object) for s in self.segments])

    def _stacked(self, key: str) -> np.ndarray:
        out = np.full((self.n_samples, 2), np.nan)
        for seg, a, b in zip(self.segments, self.bounds[:-1], self.bounds[1:]):
            out[a:b, : seg.mode.dof] = getattr(seg, key)
        out.setflags(write=False)
        return out

    @cached_property
    def s(self) -> np.ndarray:
        """Generalized coordinates ``(N, 2)`` of every sample in its segment's mode (``mode.coordinates``);
        NaN in the second column for the one-coordinate modes 3, 4 and straight."""
        return self._stacked("s")

    @cached_property
    def s_dot(self) -> np.ndarray:
        """First derivative of :attr:`s` ``(N, 2)`` (NaN-padded like it)."""
        return self._stacked("s_dot")

    @cached_property
    def s_ddot(self) -> np.ndarray:
        """Second derivative of :attr:`s` ``(N, 2)`` (NaN-padded like it)."""
        return self._stacked("s_ddot")

    @property
    def lifted(self) -> bool:
        """The wheels turn off the ground (a lifted-wheel experiment, sec. 7)."""
        return self.segments[0].lifted

    def joint_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """Planned ``(q_dot, q_ddot)`` ``(N, 9)`` of every sample, eq. (4) and (20)."""
        parts = [s.joint_motion(self.geometry) for s in self.segments]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def feedforward(self, params: Parameters, motion: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Feed-forward motor torques ``(N, 4)`` of eq. (21) with the parameters ``params``;
        ``motion``: :meth:`joint_motion` when already computed."""
        if motion is None:
            return np.concatenate([s.feedforward(self.geometry, params) for s in self.segments])
        return np.concatenate([s.feedforward(self.geometry, params, (motion[0][a:b], motion[1][a:b]))
                               for s, a, b in zip(self.segments, self.bounds[:-1], self.bounds[1:])])

    def wheel_angles(self, q_dot: np.ndarray | None = None) -> np.ndarray:
        """Planned wheel angles beta ``(N, 4)`` from 0: trapezoidal integral of the planned beta_dot."""
        if q_dot is None:
            q_dot = self.joint_motion()[0]
        return _integrate(q_dot[:, 5:], self.sample_time)

    def pose(self, q_dot: np.ndarray | None = None) -> np.ndarray:
        """Planned chassis pose ``(N, 3)`` = (X, Y, gamma) in the start frame, from the body velocities."""
        if q_dot is None:
            q_dot = self.joint_motion()[0]
        return pose_from_velocities(q_dot[:, :3], self.sample_time)

    def floor_space(self) -> FloorSpace:
        """Floor space of sec. 6.2 (:func:`floor_space`)."""
        return floor_space(self)

    def segment_slices(self) -> list[tuple[str, slice]]:
        return [(s.name, slice(int(a), int(b))) for s, a, b in zip(self.segments, self.bounds[:-1], self.bounds[1:])]


@dataclass(frozen=True)
class FloorSpace:
    """Rectangle occupied by an experiment (sec. 6.2): length along the straight motion, width."""

    length: float
    width: float

    @property
    def area(self) -> float:
        return self.length * self.width


def floor_space(traj: Trajectory) -> FloorSpace:
    """Floor space of sec. 6.2: length ``l + 2 max |x_ch|`` and width ``sqrt(l^2 + b^2) + 2a``.

    ``x_ch`` is the planned position along the chassis x axis (the longitudinal travel of every
    segment); for a lane change (mode 2) ``2 max |y|`` of the planned path is added to the width.
    """
    g = traj.geometry
    pose = traj.pose()
    x_max = float(np.max(np.abs(pose[:, 0]))) if len(pose) else 0.0
    y_max = float(np.max(np.abs(pose[:, 1])))
    return FloorSpace(g.l + 2 * x_max, math.hypot(g.l, g.b) + 2 * abs(g.a) + 2 * y_max)


def _times_columns(x: np.ndarray, H: np.ndarray) -> np.ndarray:
    """``x H^T`` ``(N, 9)`` for x ``(N, k)`` and H ``(9, k)``, summed column by column (k is 1 or 2)."""
    out = x[:, :1] * H[:, 0]
    for j in range(1, H.shape[1]):
        out += x[:, j : j + 1] * H[:, j]
    return out


def _integrate(x: np.ndarray, dt: float) -> np.ndarray:
    out = np.zeros_like(x)
    out[1:] = np.cumsum(0.5 * (x[1:] + x[:-1]) * dt, axis=0)
    return out


def pose_from_velocities(twist: np.ndarray, dt: float) -> np.ndarray:
    """World pose ``(N, 3)`` from body-frame velocities ``(N, 3)`` = (v_x, v_y, omega), trapezoidal rule."""
    gamma = _integrate(twist[:, 2:3], dt)[:, 0]
    c, s = np.cos(gamma), np.sin(gamma)
    world = np.stack([c * twist[:, 0] - s * twist[:, 1], s * twist[:, 0] + c * twist[:, 1]], axis=1)
    return np.column_stack([_integrate(world, dt), gamma])


# --- building blocks ------------------------------------------------------------------------------

def _grid(duration: float, dt: float) -> np.ndarray:
    n = int(round(duration / dt))
    if n < 2:
        raise TrajectoryError(f"duration {duration} s: expected at least two samples of {dt} s")
    return np.arange(n) * dt


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic 10u^3 - 15u^4 + 6u^5 and its first two derivatives (zero slope and curvature at 0, 1)."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2), 30 * u**2 * (1 - u) ** 2, 60 * u * (1 - u) * (1 - 2 * u)


#: Peak velocity and acceleration of the quintic smoothstep, per unit distance and duration.
_SMOOTH_PEAK_V, _SMOOTH_PEAK_A = 1.875, 10 / math.sqrt(3)


def alignment(alpha_from, alpha_to, *, rate: float = 0.8, acceleration: float = 2.0, pause: float = 0.5,
              dt: float = SAMPLE_TIME) -> Segment:
    """Wheel alignment at rest (mode 1, segment ``align``): quintic from ``alpha_from`` to ``alpha_to``
    with peak steering rate <= ``rate`` and acceleration <= ``acceleration``, held ``pause`` s before and after."""
    a0, a1 = np.asarray(alpha_from, dtype=float), np.asarray(alpha_to, dtype=float)
    dist = float(np.max(np.abs(a1 - a0)))
    move = 0.0 if dist == 0 else max(_SMOOTH_PEAK_V * dist / rate, math.sqrt(_SMOOTH_PEAK_A * dist / acceleration))
    t = _grid(2 * pause + move, dt)
    if move > 0:
        u = (t - pause) / move
        p, pd_, pdd = _smoothstep(u)
        inside = (u > 0) & (u < 1)
        pd_, pdd = pd_ * inside / move, pdd * inside / move**2
    else:
        p = pd_ = pdd = np.zeros_like(t)
    alpha = a0 + np.multiply.outer(p, a1 - a0)
    return Segment("align", Mode.PARKING, t, alpha, alpha, np.multiply.outer(pd_, a1 - a0), np.multiply.outer(pdd, a1 - a0))


def fourier_segment(name: str, mode, series: FourierSeries | tuple[FourierSeries, FourierSeries], *,
                    periods: int = 1, geom: Geometry = PROTOTYPE, dt: float = SAMPLE_TIME) -> Segment:
    """``periods`` periods of a Fourier series as a segment (it passes through rest after each period).

    Modes 3, 4 and straight take one series (``y_ch``, ``gamma_ch``, ``x_ch``) at their fixed steering
    angles; mode 1 takes two series ``(alpha_l, alpha_r)`` (a side held at zero: a series with zero
    coefficients); mode 2 (car-like) two series ``(alpha_v, x_ch)``, the steering angles following
    from alpha_v by eq. (8) (:func:`lane_change` plans the validation manoeuvre of sec. 7).
    """
    mode = Mode.from_label(mode)
    if not (isinstance(periods, int) and periods >= 1):
        raise TrajectoryError(f"segment {name!r}: periods={periods!r}: expected an integer >= 1")
    if mode in (Mode.PARKING, Mode.CAR_LIKE):
        names = "(alpha_l, alpha_r)" if mode is Mode.PARKING else "(alpha_v, x_ch)"
        if not (isinstance(series, tuple) and len(series) == 2):
            raise TrajectoryError(f"segment {name!r} in mode {mode.label}: expected two series {names}")
        if series[0].base_frequency != series[1].base_frequency:
            raise TrajectoryError(f"segment {name!r}: the two series need the same base frequency")
        t = _grid(series[0].period * periods, dt)
        parts = [np.stack(x, axis=1) for x in zip(series[0].evaluate(t), series[1].evaluate(t))]
        if mode is Mode.PARKING:
            return Segment(name, mode, t, parts[0], parts[0], parts[1], parts[2])
        limit = max_virtual_angle(geom)
        if np.max(np.abs(parts[0][:, 0])) > limit:
            raise TrajectoryError(f"segment {name!r}: |alpha_v| reaches {np.max(np.abs(parts[0][:, 0])):.4g} rad, "
                                  f"beyond the stops ({limit:.4g} rad): expected a smaller steering series")
        return Segment(name, mode, t, steering_from_virtual(geom, parts[0][:, 0]), parts[0], parts[1], parts[2])
    nominal = nominal_steering(geom, mode)
    if nominal is None or isinstance(series, tuple):
        raise TrajectoryError(f"segment {name!r}: mode {mode.label} takes one Fourier series; mode 2 see lane_change()")
    t = _grid(series.period * periods, dt)
    q, qd, qdd = series.evaluate(t)
    return Segment(name, mode, t, np.tile(nominal, (len(t), 1)), q[:, None], qd[:, None], qdd[:, None])


# Default excitation (methods are data): velocity-coefficient shapes (a, b), projected to start and
