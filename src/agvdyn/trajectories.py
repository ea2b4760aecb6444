"""Planned motions: Fourier excitation (sec. 6.2), the identification sequence, the lane change
of sec. 7, the lateral experiment, and user trajectories read from files.

A :class:`Trajectory` is a tuple of :class:`Segment` objects sampled at ``T_s``. Each segment
has one motion mode k and carries the generalized coordinates ``s_k`` of eq. (10)-(13) with
their first two time derivatives, and the steering angles ``alpha`` of every sample, so that
``agvdyn.kinematics.joint_motion`` gives ``q_dot, q_ddot`` (eq. 4, 20) and
``agvdyn.dynamics.feedforward_torques`` the motor torques of eq. (21).

Generalized coordinates per mode (PLATFORM.md): mode 1 ``(alpha_l, alpha_r)``, mode 2
``(alpha_v, x_ch)``, mode 3 ``y_ch``, mode 4 ``gamma_ch``, straight ``x_ch``; ``x_ch`` and
``y_ch`` are distances travelled along the chassis axes (integrals of ``v_x``, ``v_y``).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from agvdyn.dynamics import feedforward_torques
from agvdyn.kinematics import (
    MODE_TOLERANCE,
    Mode,
    check_mode,
    joint_motion,
    max_virtual_angle,
    nominal_steering,
    steering_from_virtual,
    virtual_from_steering,
)
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME, Geometry, Parameters

#: Largest jump of the steering angles (rad) allowed between the end of a segment and the next one.
CONTINUITY_TOLERANCE = 1e-3
#: Segment names of PLATFORM.md (the ``segment`` column of a log).
SEGMENT_NAMES = ("steer_left", "steer_right", "straight", "rotation", "lateral", "lane_change", "align")


class TrajectoryError(ValueError):
    """A trajectory that cannot be planned or read; the message names the source and the value."""


class LimitError(TrajectoryError):
    """A planned trajectory breaks a limit; the message names the limit, segment, time and value."""


# --- Fourier series, sec. 6.2 ---------------------------------------------------------------------

@dataclass(frozen=True)
class FourierSeries:
    """Finite Fourier series of one coordinate (Swevers et al. 1997, as in sec. 6.2 of the paper).

    ``q(t) = q_0 + sum_k [a_k/(k w) sin(k w t) - b_k/(k w) cos(k w t)]``, k = 1..n, so that
    ``q_dot(t) = sum_k [a_k cos(k w t) + b_k sin(k w t)]``. Built with :meth:`at_rest` the series
    starts and ends (one period ``2 pi / w`` later) at ``start`` with zero velocity and
    acceleration.

    Parameters
    ----------
    base_frequency : w, rad/s; the segment lasts one period 2 pi / w.
    a, b : velocity amplitudes of the cosine and sine terms (unit of q per second).
    start : q(0) = q(2 pi / w).
    """

    base_frequency: float
    a: tuple[float, ...]
    b: tuple[float, ...]
    start: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.base_frequency) and self.base_frequency > 0):
            raise TrajectoryError(f"base_frequency={self.base_frequency!r}: expected a finite number > 0 rad/s")
        a, b = tuple(float(x) for x in self.a), tuple(float(x) for x in self.b)
        if len(a) != len(b) or not a:
            raise TrajectoryError(f"Fourier coefficients a ({len(a)}) and b ({len(b)}): expected the same number >= 1")
        if not all(math.isfinite(x) for x in a + b + (self.start,)):
            raise TrajectoryError(f"Fourier coefficients a={a}, b={b}, start={self.start}: expected finite numbers")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)

    @classmethod
    def at_rest(cls, base_frequency: float, a, b, start: float = 0.0, peak_velocity: float | None = None,
                peak_excursion: float | None = None) -> "FourierSeries":
        """Series that starts and ends at rest: the nearest coefficients (least squares) with
        ``sum a_k = 0`` (zero velocity) and ``sum k b_k = 0`` (zero acceleration) at t = 0,
        optionally scaled down so that ``max |q_dot| <= peak_velocity`` and
        ``max |q - start| <= peak_excursion`` (one of them reached)."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        k = np.arange(1, len(a) + 1, dtype=float)
        if a.shape != b.shape or a.ndim != 1:
            raise TrajectoryError(f"Fourier coefficients of shapes {a.shape}, {b.shape}: expected two equal 1-d lists")
        a = a - a.mean()
        b = b - k * (k @ b) / (k @ k)
        series = cls(base_frequency, tuple(a), tuple(b), start)
        if peak_velocity is None and peak_excursion is None:
            return series
        q, qd, _ = series.evaluate(np.linspace(0, series.period, 8001))
        peak_v, peak_q = np.max(np.abs(qd)), np.max(np.abs(q - start))
        if peak_v <= 0:
            raise TrajectoryError("Fourier coefficients give no motion: cannot scale them to a peak")
        scale = min(np.inf if peak_velocity is None else peak_velocity / peak_v,
                    np.inf if peak_excursion is None else peak_excursion / peak_q)
        return cls(base_frequency, tuple(a * scale), tuple(b * scale), start)

    @property
    def period(self) -> float:
        """2 pi / w, s."""
        return 2 * math.pi / self.base_frequency

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, q_dot, q_ddot)`` at the times t ``(N,)``."""
        t = np.asarray(t, dtype=float)
        w = self.base_frequency
        k = np.arange(1, len(self.a) + 1, dtype=float)
        a, b = np.array(self.a), np.array(self.b)
        phase = np.multiply.outer(t, k * w)
        s, c = np.sin(phase), np.cos(phase)
        q0 = self.start + np.sum(b / (k * w))
        q = q0 + s @ (a / (k * w)) - c @ (b / (k * w))
        qd = c @ a + s @ b
        qdd = (-s @ (a * k * w)) + c @ (b * k * w)
        return q, qd, qdd

    def to_dict(self) -> dict[str, Any]:
        return {"base_frequency": self.base_frequency, "a": list(self.a), "b": list(self.b), "start": self.start}


# --- segments and trajectories --------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Segment:
    """One phase of a planned motion in one motion mode, sampled at ``sample_time``.

    ``t`` starts at 0; ``alpha`` is ``(N, 2)``; ``s``, ``s_dot``, ``s_ddot`` are ``(N, n_k)`` in the
    coordinates of ``mode.coordinates``.
    """

    name: str
    mode: Mode
    t: np.ndarray
    alpha: np.ndarray
    s: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray

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

    def joint_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """Planned ``(q_dot, q_ddot)`` ``(N, 9)`` of every sample, eq. (4) and (20)."""
        parts = [joint_motion(self.geometry, s.mode, s.alpha, s.s_dot, s.s_ddot) for s in self.segments]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def feedforward(self, params: Parameters) -> np.ndarray:
        """Feed-forward motor torques ``(N, 4)`` of eq. (21) with the parameters ``params``."""
        return np.concatenate([
            feedforward_torques(self.geometry, params, s.mode, s.alpha, s.s_dot, s.s_ddot) for s in self.segments
        ])

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

    def floor_space(self) -> "FloorSpace":
        return floor_space(self)

    def segment_slices(self) -> list[tuple[str, slice]]:
        return [(s.name, slice(int(a), int(b))) for s, a, b in zip(self.segments, self.bounds[:-1], self.bounds[1:])]


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
    coefficients). Mode 2 is planned with :func:`lane_change`.
    """
    mode = Mode.from_label(mode)
    if not (isinstance(periods, int) and periods >= 1):
        raise TrajectoryError(f"segment {name!r}: periods={periods!r}: expected an integer >= 1")
    if mode is Mode.PARKING:
        if not (isinstance(series, tuple) and len(series) == 2):
            raise TrajectoryError(f"segment {name!r} in mode 1: expected two series (alpha_l, alpha_r)")
        if series[0].base_frequency != series[1].base_frequency:
            raise TrajectoryError(f"segment {name!r}: the two series need the same base frequency")
        t = _grid(series[0].period * periods, dt)
        parts = [np.stack(x, axis=1) for x in zip(series[0].evaluate(t), series[1].evaluate(t))]
        return Segment(name, mode, t, parts[0], parts[0], parts[1], parts[2])
    nominal = nominal_steering(geom, mode)
    if nominal is None or isinstance(series, tuple):
        raise TrajectoryError(f"segment {name!r}: mode {mode.label} takes one Fourier series; mode 2 see lane_change()")
    t = _grid(series.period * periods, dt)
    q, qd, qdd = series.evaluate(t)
    return Segment(name, mode, t, np.tile(nominal, (len(t), 1)), q[:, None], qd[:, None], qdd[:, None])


# Default excitation (methods are data): velocity-coefficient shapes (a, b), projected to start and
# end at rest, then scaled to the peak velocity or the peak excursion, whichever is reached first.
# Steering: 6 harmonics of 8 s (0.8-4.7 rad/s), three periods, so that C_l alpha_ddot is not
# negligible against the large steering friction; straight and rotation: 5 harmonics of 30 s.
# The shapes were picked among random draws for the lowest cond(Theta_1w^T Theta_1w) of the
# planned sequence (about 8.5; the paper reports 11.56).
#            name: (shape a, shape b), period s, peak velocity, peak excursion, periods
_EXCITATION = {
    "steer_left": (((-0.1, 0.1, 0.04, -0.51, 0.59, 0.89), (0.32, -0.82, 0.73, -0.5, 0.88, -1.07)), 8.0, 1.5, 0.9, 3),
    "steer_right": (((0.91, -0.02, -1.25, -0.31, 0.05, 0.27), (-0.98, -1.11, 0.2, -0.47, 0.24, 0.76)), 8.0, 1.5, 0.9, 3),
    "straight": (((-1.65, 0.25, 1.22, -0.3, -0.81), (0.75, 0.25, 0.9, -0.35, -1.48)), 30.0, 0.8, 2.0, 1),
    "rotation": (((-0.11, -0.45, 0.78, 0.19, -1.63), (-1.2, 0.88, 0.68, -0.64, 0.0)), 30.0, 0.7, 1.6, 1),
    "lateral": (((1.0, 0.4, -0.6, 0.5, 0.3), (0.5, -0.7, 0.6, -0.4, 0.3)), 24.0, 0.5, 1.5, 1),
}


def default_excitation(name: str) -> FourierSeries:
    """Default Fourier series of a segment of the identification sequence (or ``lateral``).

    steer_left / steer_right: period 8 s, |alpha_dot| <= 1.5 rad/s, |alpha| <= 0.9 rad (three periods);
    straight: 30 s, |v_x| <= 0.8 m/s, |x_ch| <= 2 m; rotation: 30 s, |omega| <= 0.7 rad/s,
    |gamma| <= 1.6 rad; lateral: 24 s, |v_y| <= 0.5 m/s, |y_ch| <= 1.5 m.
    """
    if name not in _EXCITATION:
        raise TrajectoryError(f"no default excitation for {name!r}: expected one of {sorted(_EXCITATION)}")
    (a, b), period, peak_v, peak_q, _ = _EXCITATION[name]
    return FourierSeries.at_rest(2 * math.pi / period, a, b, peak_velocity=peak_v, peak_excursion=peak_q)


def default_periods(name: str) -> int:
    """Number of periods of the default excitation of a segment."""
    return _EXCITATION[name][4]


def _zero_series(like: FourierSeries) -> FourierSeries:
    return FourierSeries(like.base_frequency, (0.0,) * len(like.a), (0.0,) * len(like.b))


def identification_sequence(geom: Geometry = PROTOTYPE, *, steer_left: FourierSeries | None = None,
                            steer_right: FourierSeries | None = None, straight: FourierSeries | None = None,
                            rotation: FourierSeries | None = None, steering_periods: int | None = None,
                            pause: float = 0.5, dt: float = SAMPLE_TIME) -> Trajectory:
    """Identification sequence of sec. 6.2: steer_left, steer_right, straight, rotation.

    Mode 1 with one side held at zero, straight motion (mode 2, alpha_v = 0), pure rotation
    (mode 4), with ``align`` segments at rest between them (a ``pause`` when the wheels need not
    turn; before the rotation the wheels turn to arctan(l/b) (-1, 1) and back to zero after it).
    The steering series run ``steering_periods`` periods (default: 3 with the default series, else 1).
    """
    periods = steering_periods or (default_periods("steer_left") if steer_left is None and steer_right is None else 1)
    sl = steer_left or default_excitation("steer_left")
    sr = steer_right or default_excitation("steer_right")
    zero2 = np.zeros(2)
    rot = nominal_steering(geom, Mode.ROTATION)
    segs = [
        alignment(zero2, zero2, pause=pause, dt=dt),
        fourier_segment("steer_left", Mode.PARKING, (sl, _zero_series(sl)), periods=periods, geom=geom, dt=dt),
        alignment(zero2, zero2, pause=pause, dt=dt),
        fourier_segment("steer_right", Mode.PARKING, (_zero_series(sr), sr), periods=periods, geom=geom, dt=dt),
        alignment(zero2, zero2, pause=pause, dt=dt),
        fourier_segment("straight", Mode.STRAIGHT, straight or default_excitation("straight"), geom=geom, dt=dt),
        alignment(zero2, rot, pause=pause, dt=dt),
        fourier_segment("rotation", Mode.ROTATION, rotation or default_excitation("rotation"), geom=geom, dt=dt),
        alignment(rot, zero2, pause=pause, dt=dt),
    ]
    return Trajectory(tuple(segs), geom, dt, "identification")


def lateral_experiment(geom: Geometry = PROTOTYPE, *, series: FourierSeries | None = None, pause: float = 0.5,
                       dt: float = SAMPLE_TIME) -> Trajectory:
    """Lateral motion (mode 3): wheels aligned to the stops (-pi/2, pi/2), a Fourier series in y_ch, back to zero."""
    stops = nominal_steering(geom, Mode.LATERAL)
    zero2 = np.zeros(2)
    segs = (
        alignment(zero2, stops, pause=pause, dt=dt),
        fourier_segment("lateral", Mode.LATERAL, series or default_excitation("lateral"), geom=geom, dt=dt),
        alignment(stops, zero2, pause=pause, dt=dt),
    )
    return Trajectory(segs, geom, dt, "lateral")


def _lane_change_amplitude(offset: float, length: float) -> float:
    """Heading amplitude A of psi(u) = A sin^4(pi u) with int_0^L sin(psi) d sigma = offset."""
    u = np.linspace(0.0, 1.0, 4001)
    lateral = lambda A: np.trapezoid(np.sin(A * np.sin(np.pi * u) ** 4), u) * length - offset  # noqa: E731
    if abs(offset) >= 0.375 * length * 0.999:  # int sin^4 = 3/8: beyond it the heading would pass 90 deg
        raise TrajectoryError(f"lane change offset {offset} m over {length} m: expected |offset| < 0.375 * length")
    return float(brentq(lateral, -math.pi / 2, math.pi / 2))


def lane_change(geom: Geometry = PROTOTYPE, *, speed: float = 0.8, offset: float = 1.5, length: float = 8.0,
                acceleration: float = 0.4, straight_before: float = 1.0, straight_after: float = 1.0,
                dt: float = SAMPLE_TIME) -> Trajectory:
    """Lane change in the car-like mode (mode 2, sec. 7): validation trajectory.

    The chassis accelerates from rest to ``speed`` (quintic speed profile, peak ``acceleration``),
    drives ``straight_before`` m, changes lane by ``offset`` m (left positive) over ``length`` m of
    path, drives ``straight_after`` m and stops. The heading along the path is
    ``psi = A sin^4(pi u)``, u in [0, 1], so curvature and its first two derivatives vanish at both
    ends; the virtual steering angle is ``alpha_v = arctan(kappa l / 2)`` (``omega = 2 v_x tan(alpha_v)/l``,
    PLATFORM.md) and ``alpha = f_ICR(alpha_v)`` (eq. 8).
    """
    if not (speed > 0 and acceleration > 0 and length > 0):
        raise TrajectoryError(f"lane change speed={speed}, acceleration={acceleration}, length={length}: expected > 0")
    amp = _lane_change_amplitude(offset, length)
    t_acc = _SMOOTH_PEAK_V * speed / acceleration  # peak acceleration of v = V p(t/T) is 1.875 V/T
    d_acc = speed * t_acc / 2
    d_total = 2 * d_acc + straight_before + length + straight_after
    t_cruise = (d_total - 2 * d_acc) / speed
    t = _grid(2 * t_acc + t_cruise + 1.0, dt)  # plus 1 s at rest at the end
    p1, p1d, p1dd = _smoothstep(t / t_acc)
    p2, p2d, p2dd = _smoothstep((t - t_acc - t_cruise) / t_acc)
    v = speed * (p1 - p2)
    vd = speed * (p1d - p2d) / t_acc
    # distance: integral of the smoothstep is T (u^4 (5/2 - 3u + u^2)) for u in [0, 1]
    def dist(tt):
        u = np.clip(tt / t_acc, 0, 1)
        return t_acc * u**4 * (2.5 - 3 * u + u**2) + np.maximum(tt - t_acc, 0)
    sigma = speed * (dist(t) - dist(t - t_acc - t_cruise))
    u = (sigma - d_acc - straight_before) / length
    inside = (u > 0) & (u < 1)
    k = math.pi / length
    sn, cs = np.sin(math.pi * np.clip(u, 0, 1)), np.cos(math.pi * np.clip(u, 0, 1))
    kappa = inside * amp * 4 * k * sn**3 * cs
    dkappa = inside * amp * 4 * k**2 * (3 * sn**2 * cs**2 - sn**4)
    ddkappa = inside * amp * 4 * k**3 * (6 * sn * cs**3 - 10 * sn**3 * cs)
    h = geom.l / 2
    alpha_v = np.arctan(kappa * h)
    f1 = h / (1 + (kappa * h) ** 2)
    f2 = -2 * h**3 * kappa / (1 + (kappa * h) ** 2) ** 2
    av_dot = f1 * dkappa * v
    av_ddot = f2 * (dkappa * v) ** 2 + f1 * (ddkappa * v**2 + dkappa * vd)
    if np.max(np.abs(alpha_v)) > max_virtual_angle(geom):
        raise LimitError(f"lane change: |alpha_v| reaches {np.max(np.abs(alpha_v)):.3f} rad beyond the stops "
                         f"({max_virtual_angle(geom):.3f}): expected a longer lane change or a smaller offset")
    alpha = steering_from_virtual(geom, alpha_v)
    s = np.stack([alpha_v, sigma], axis=1)
    seg = Segment("lane_change", Mode.CAR_LIKE, t, alpha, s, np.stack([av_dot, v], axis=1),
                  np.stack([av_ddot, vd], axis=1))
    return Trajectory((seg,), geom, dt, "lane_change")


# --- limits and floor space ---------------------------------------------------------------------

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
        "steering_rate": np.abs(qd[:, 3:5]).max(axis=1),
        "steering_acceleration": np.abs(qdd[:, 3:5]).max(axis=1),
        "speed": np.hypot(qd[:, 0], qd[:, 1]),
        "acceleration": np.hypot(qdd[:, 0], qdd[:, 1]),
        "yaw_rate": np.abs(qd[:, 2]),
        "yaw_acceleration": np.abs(qdd[:, 2]),
        "wheel_speed": np.abs(qd[:, 5:]).max(axis=1),
        "motor_torque": np.abs(u).max(axis=1),
    }
    lim = {k: getattr(limits, k) for k in values}
    lim["motor_torque"] = limits.motor_torque * limits.feedforward_share
    peaks, worst = {}, {}
    for k, v in values.items():
        i = int(np.argmax(v))
        peaks[k] = float(v[i])
        worst[k] = (str(traj.segment[i]), float(traj.t[i]))
    return LimitReport(peaks, lim, worst)


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


# --- user trajectories from files ----------------------------------------------------------------

_CSV_COORD = {Mode.CAR_LIKE: "x_ch", Mode.STRAIGHT: "x_ch", Mode.LATERAL: "y_ch", Mode.ROTATION: "gamma_ch"}


def read_trajectory(path: str | os.PathLike, geom: Geometry = PROTOTYPE, *, dt: float = SAMPLE_TIME,
                    tolerance: float = MODE_TOLERANCE) -> Trajectory:
    """Read a user trajectory (CSV sample by sample, or YAML segment by segment); see docs/simulation.md.

    CSV columns: ``t`` (s, increasing), ``mode`` (1, 2, 3, 4 or 2s/straight), ``alpha_l``, ``alpha_r``
    (rad), and the chassis coordinate the mode needs: ``x_ch`` (modes 2 and straight, m),
    ``y_ch`` (mode 3, m), ``gamma_ch`` (mode 4, rad); optional ``segment``. Consecutive rows of one
    mode and segment form a segment; each is interpolated by cubic splines onto the grid of ``dt``,
    which gives the derivatives. The file is never modified.

    YAML: ``segments:`` a list of ``{name, mode, fourier: {base_frequency, a, b}}`` (mode 1:
    ``fourier: {alpha_l: {...}, alpha_r: {...}}``), ``{name: align, to: [alpha_l, alpha_r]}`` or
    ``{name: lane_change, speed, offset, length, ...}`` (the arguments of :func:`lane_change`).
    """
    path = Path(path)
    if not path.exists():
        raise TrajectoryError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _read_csv_trajectory(path, geom, dt, tolerance)
    if suffix in (".yaml", ".yml"):
        return _read_yaml_trajectory(path, geom, dt)
    raise TrajectoryError(f"{path}: unknown trajectory format {suffix!r}: expected .csv, .yaml or .yml")


def _read_csv_trajectory(path: Path, geom: Geometry, dt: float, tolerance: float) -> Trajectory:
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise TrajectoryError(f"{path}: cannot be read as CSV: {exc}") from exc
    for col in ("t", "mode", "alpha_l", "alpha_r"):
        if col not in frame.columns:
            raise TrajectoryError(f"{path}: missing column {col!r}: expected t, mode, alpha_l, alpha_r "
                                  "and x_ch / y_ch / gamma_ch as the modes need")
    try:
        modes = [Mode.from_label(m) for m in frame["mode"].astype(str)]
    except ValueError as exc:
        bad = next(i for i, m in enumerate(frame["mode"].astype(str)) if not _is_mode(m))
        raise TrajectoryError(f"{path}: column 'mode', row {bad + 2}: {exc}") from exc
    names = frame["segment"].astype(str).tolist() if "segment" in frame.columns else [
        {Mode.PARKING: "align", Mode.CAR_LIKE: "lane_change", Mode.LATERAL: "lateral",
         Mode.ROTATION: "rotation", Mode.STRAIGHT: "straight"}[m] for m in modes]
    t = _csv_numbers(path, frame, "t")
    if np.any(np.diff(t) <= 0):
        row = int(np.argmax(np.diff(t) <= 0)) + 1
        raise TrajectoryError(f"{path}: column 't', row {row + 2}: t = {t[row]} is not after {t[row - 1]}: "
                              "expected strictly increasing times")
    alpha = np.stack([_csv_numbers(path, frame, "alpha_l"), _csv_numbers(path, frame, "alpha_r")], axis=1)
    keys = list(zip(modes, names))
    starts = [0] + [i for i in range(1, len(keys)) if keys[i] != keys[i - 1]] + [len(keys)]
    segs = []
    for a, b in zip(starts[:-1], starts[1:]):
        mode, name = keys[a]
        if b - a < 4:
            raise TrajectoryError(f"{path}: rows {a + 2}-{b + 1} (segment {name!r}, mode {mode.label}): "
                                  "expected at least 4 rows per segment for the spline")
        try:
            check_mode(geom, mode, alpha[a:b], tolerance)
        except ValueError as exc:
            raise TrajectoryError(f"{path}: rows {a + 2}-{b + 1}: {exc}") from exc
        tt = t[a:b] - t[a]
        grid = _grid(tt[-1] + dt, dt)
        grid = grid[grid <= tt[-1] + 1e-12]
        if mode is Mode.PARKING:
            coords = alpha[a:b]
        elif mode is Mode.CAR_LIKE:
            coords = np.column_stack([virtual_from_steering(geom, alpha[a:b]), _csv_numbers(path, frame, "x_ch")[a:b]])
        else:
            coords = _csv_numbers(path, frame, _CSV_COORD[mode])[a:b, None]
        spline = CubicSpline(tt, coords, axis=0)
        s, sd, sdd = spline(grid), spline(grid, 1), spline(grid, 2)
        if mode is Mode.PARKING:
            al = s
        elif mode is Mode.CAR_LIKE:
            al = steering_from_virtual(geom, np.clip(s[:, 0], -max_virtual_angle(geom), max_virtual_angle(geom)))
        else:
            al = np.tile(nominal_steering(geom, mode), (len(grid), 1))
        try:
            segs.append(Segment(name, mode, grid, al, s, sd, sdd))
        except TrajectoryError as exc:
            raise TrajectoryError(f"{path}: rows {a + 2}-{b + 1}: {exc}") from exc
    return Trajectory(tuple(segs), geom, dt, path.stem)


def _is_mode(label: str) -> bool:
    try:
        Mode.from_label(label)
        return True
    except ValueError:
        return False


def _csv_numbers(path: Path, frame: pd.DataFrame, col: str) -> np.ndarray:
    if col not in frame.columns:
        raise TrajectoryError(f"{path}: missing column {col!r}, needed by the modes in the file")
    values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad))
        raise TrajectoryError(f"{path}: column {col!r}, row {row + 2}: {frame[col].iloc[row]!r}: expected a finite number")
    return values


def _series_from(path: Path, where: str, spec: Any) -> FourierSeries:
    if not isinstance(spec, dict) or "base_frequency" not in spec or "a" not in spec or "b" not in spec:
        raise TrajectoryError(f"{path}: {where}: expected a mapping with base_frequency, a, b")
    try:
        return FourierSeries.at_rest(float(spec["base_frequency"]), spec["a"], spec["b"], float(spec.get("start", 0.0)),
                                     peak_velocity=spec.get("peak_velocity"))
    except (TypeError, ValueError) as exc:
        raise TrajectoryError(f"{path}: {where}: {exc}") from exc


def _read_yaml_trajectory(path: Path, geom: Geometry, dt: float) -> Trajectory:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise TrajectoryError(f"{path}: cannot be read as YAML: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get("segments"), list) or not data["segments"]:
        raise TrajectoryError(f"{path}: expected a mapping with a non-empty list 'segments'")
    segs: list[Segment] = []
    alpha_now = np.zeros(2)
    for i, spec in enumerate(data["segments"]):
        where = f"segments[{i}]"
        if not isinstance(spec, dict) or "name" not in spec:
            raise TrajectoryError(f"{path}: {where}: expected a mapping with a 'name'")
        name = str(spec["name"])
        try:
            if name == "align":
                target = np.asarray(spec.get("to", alpha_now), dtype=float)
                seg = alignment(alpha_now, target, pause=float(spec.get("pause", 0.5)),
                                rate=float(spec.get("rate", 0.8)), dt=dt)
            elif name == "lane_change" and "fourier" not in spec:
                keys = {"speed", "offset", "length", "acceleration", "straight_before", "straight_after"}
                unknown = set(spec) - keys - {"name", "mode"}
                if unknown:
                    raise TrajectoryError(f"unknown keys {sorted(unknown)}: expected some of {sorted(keys)}")
                seg = lane_change(geom, dt=dt, **{k: float(v) for k, v in spec.items() if k in keys}).segments[0]
            else:
                mode = Mode.from_label(spec.get("mode", ""))
                four = spec.get("fourier")
                if mode is Mode.PARKING:
                    if not isinstance(four, dict):
                        raise TrajectoryError("mode 1 needs fourier: {alpha_l: {...}, alpha_r: {...}}")
                    parts = []
                    for side, j in (("alpha_l", 0), ("alpha_r", 1)):
                        parts.append(_series_from(path, f"{where}.fourier.{side}", four[side]) if side in four else None)
                    ref = next(p for p in parts if p is not None)
                    parts = [p or FourierSeries(ref.base_frequency, (0.0,) * len(ref.a), (0.0,) * len(ref.a),
                                                float(alpha_now[j])) for j, p in enumerate(parts)]
                    seg = fourier_segment(name, mode, (parts[0], parts[1]), geom=geom, dt=dt)
                else:
                    seg = fourier_segment(name, mode, _series_from(path, f"{where}.fourier", four), geom=geom, dt=dt)
        except (TrajectoryError, ValueError, KeyError, StopIteration) as exc:
            raise TrajectoryError(f"{path}: {where} ({name}): {exc}") from exc
        if np.max(np.abs(seg.alpha[0] - alpha_now)) > CONTINUITY_TOLERANCE:
            raise TrajectoryError(
                f"{path}: {where} ({name}) starts at alpha = ({seg.alpha[0, 0]:.6g}, {seg.alpha[0, 1]:.6g}) but the "
                f"previous segment ends at ({alpha_now[0]:.6g}, {alpha_now[1]:.6g}): insert an 'align' segment")
        alpha_now = seg.alpha[-1].copy()
        segs.append(seg)
    return Trajectory(tuple(segs), geom, dt, path.stem)


def experiment(name: str, geom: Geometry = PROTOTYPE, *, dt: float = SAMPLE_TIME) -> Trajectory:
    """Built-in experiment by name (``identification``, ``lane-change``, ``lateral``) or a trajectory file."""
    key = name.strip().lower().replace("_", "-")
    if key == "identification":
        return identification_sequence(geom, dt=dt)
    if key == "lane-change":
        return lane_change(geom, dt=dt)
    if key == "lateral":
        return lateral_experiment(geom, dt=dt)
    if Path(name).suffix.lower() in (".csv", ".yaml", ".yml"):
        return read_trajectory(name, geom, dt=dt)
    raise TrajectoryError(f"unknown experiment {name!r}: expected identification, lane-change, lateral "
                          "or a trajectory file (.csv, .yaml)")
