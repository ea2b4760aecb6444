"""The ``driving`` experiment: a warehouse shift (issue 31), test data of payload tracking.

A random route on a rectangular floor (``floor`` = length x width in m, centred at the start, the
vehicle first heading +x): straight runs that accelerate from rest and brake to rest (quintic
position profiles at a random peak speed), lane changes in the car-like mode (sec. 7's manoeuvre),
rotations in place by +-90 or 180 degrees between the axis directions, and stops. Each manoeuvre is
drawn with ``numpy.random.default_rng(seed)`` until ``duration`` s are planned; a run or lane change
that would leave the floor (with a ``margin`` around the vehicle's footprint) is shortened, or the
vehicle turns towards the widest free direction. Every manoeuvre starts and ends at rest with the
wheels straight, so loads can be picked up at any stop. The speeds, accelerations and yaw rates stay
well inside :class:`~agvdyn.trajectories.limits.Limits` (checked by ``simulate``) with room for
+60 % of payload on the controller's feedback.
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn.kinematics import Mode, nominal_steering
from agvdyn.platform import PROTOTYPE, SAMPLE_TIME, Geometry
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import lane_change
from agvdyn.trajectories.limits import Limits
from agvdyn.trajectories.segments import (
    _SMOOTH_PEAK_A,
    _SMOOTH_PEAK_V,
    Segment,
    Trajectory,
    _grid,
    _smoothstep,
    alignment,
    pose_from_velocities,
)

__all__ = ["driving_experiment"]

#: Probabilities of the manoeuvres: straight run, lane change, rotation, stop.
MANOEUVRES = (("straight", 0.3), ("lane_change", 0.35), ("rotation", 0.2), ("stop", 0.15))


def _rest_to_rest(name: str, mode: Mode, distance: float, peak_rate: float, peak_acceleration: float,
                  alpha: np.ndarray, dt: float) -> Segment:
    """Quintic move of one coordinate by ``distance`` from rest to rest within a peak rate and acceleration."""
    d = abs(distance)
    T = max(_SMOOTH_PEAK_V * d / peak_rate, math.sqrt(_SMOOTH_PEAK_A * d / peak_acceleration))
    t = _grid(T + dt, dt)
    p, pd_, pdd = _smoothstep(t / T)
    s = distance * p
    return Segment(name, mode, t, np.tile(alpha, (t.size, 1)), s[:, None], (distance * pd_ / T)[:, None],
                   (distance * pdd / T**2)[:, None])


def _free(pose: np.ndarray, heading: float, floor: tuple[float, float], margin: float) -> float:
    """Distance the vehicle's centre can travel along ``heading`` before ``margin`` from a wall."""
    half = (floor[0] / 2 - margin, floor[1] / 2 - margin)
    c, s = math.cos(heading), math.sin(heading)
    out = math.inf
    for k, direction in ((0, c), (1, s)):
        if abs(direction) > 1e-9:
            wall = half[k] if direction > 0 else -half[k]
            out = min(out, (wall - pose[k]) / direction)
    return max(out, 0.0)


def _end_pose(pose: np.ndarray, segs: list[Segment], geom: Geometry, dt: float) -> np.ndarray:
    """World pose after the segments ``segs`` driven from ``pose``."""
    for seg in segs:
        local = pose_from_velocities(seg.joint_motion(geom)[0][:, :3], dt)[-1]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose = np.array([pose[0] + c * local[0] - s * local[1], pose[1] + s * local[0] + c * local[1],
                         pose[2] + local[2]])
    return pose


def _rotation(geom: Geometry, angle: float, yaw_rate: float, yaw_acceleration: float, dt: float) -> list[Segment]:
    zero, spin = np.zeros(2), nominal_steering(geom, Mode.ROTATION)
    turn = _rest_to_rest("rotation", Mode.ROTATION, angle, yaw_rate, yaw_acceleration, spin, dt)
    return [alignment(zero, spin, pause=0.3, dt=dt), turn, alignment(spin, zero, pause=0.3, dt=dt)]


def _turn_towards_space(pose: np.ndarray, floor: tuple[float, float], margin: float, rng) -> float:
    """Rotation angle (+-pi/2 or pi) to the axis direction with the most free floor (ties at random)."""
    options = [(_free(pose, pose[2] + a, floor, margin) + rng.uniform(0, 0.5), a) for a in (math.pi / 2, -math.pi / 2,
                                                                                           math.pi)]
    return max(options)[1]


def _manoeuvre(kind: str, pose: np.ndarray, geom: Geometry, floor: tuple[float, float], rng,
               speed: float, acceleration: float, yaw_rate: float, yaw_acceleration: float, margin: float,
               dt: float) -> list[Segment]:
    zero = np.zeros(2)
    free = _free(pose, pose[2], floor, margin)
    if kind == "stop":
        return [alignment(zero, zero, pause=float(rng.uniform(0.5, 1.5)), dt=dt)]
    if kind == "lane_change" and free > 5.0:
        v = float(rng.uniform(0.5, speed))
        length = float(rng.uniform(3.0, min(7.0, free - 2.0)))
        room = [_free(pose, pose[2] + a, floor, margin) for a in (math.pi / 2, -math.pi / 2)]
        side = 1.0 if room[0] >= room[1] else -1.0
        offset = side * min(float(rng.uniform(0.5, 1.5)), 0.3 * length, max(room) - 0.1)
        for _ in range(6):  # slower until the steering turns at most at 60 % of its rate limit
            lane = lane_change(geom, speed=v, offset=offset, length=length, acceleration=acceleration,
                               straight_before=0.3, straight_after=0.3, dt=dt)
            rate = float(np.abs(lane.joint_motion()[0][:, 3:5]).max())
            if rate <= 0.6 * Limits().steering_rate:
                break
            v *= 0.6 * Limits().steering_rate / rate
        if _free(pose, pose[2], floor, margin) >= float(np.ptp(lane.pose()[:, 0])) and abs(offset) >= 0.3:
            return list(lane.segments)
    if kind in ("straight", "lane_change") and free > 1.0:
        distance = float(rng.uniform(1.0, min(10.0, free)))
        return [_rest_to_rest("straight", Mode.STRAIGHT, distance, float(rng.uniform(0.4, speed)), acceleration,
                              zero, dt)]
    angle = _turn_towards_space(pose, floor, margin, rng) if free <= 3.0 or kind == "rotation" else math.pi
    return _rotation(geom, angle, yaw_rate, yaw_acceleration, dt)


def driving_experiment(geom: Geometry = PROTOTYPE, *, duration: float = 300.0, floor: tuple[float, float] = (20.0, 10.0),
                       seed: int = 0, speed: float = 1.0, acceleration: float = 0.5, yaw_rate: float = 0.8,
                       yaw_acceleration: float = 1.5, dt: float = SAMPLE_TIME) -> Trajectory:
    """A warehouse shift of about ``duration`` s on a ``floor`` (length, width) m (module docstring):
    straight runs (peak ``speed`` m/s, ``acceleration`` m/s^2), lane changes, rotations (``yaw_rate``
    rad/s, ``yaw_acceleration`` rad/s^2) and stops, drawn with ``seed``."""
    length, width = (float(x) for x in floor)
    margin = 0.5 * math.hypot(geom.l, geom.b) + abs(geom.a) + 0.3
    if not (duration > 0 and min(length, width) > 2 * margin + 1.0):
        raise TrajectoryError(f"driving: duration={duration}, floor={floor}: expected a duration > 0 s and a floor "
                              f"wider than {2 * margin + 1.0:.2f} m both ways (the vehicle turns in it)")
    if not (speed > 0 and acceleration > 0 and yaw_rate > 0 and yaw_acceleration > 0):
        raise TrajectoryError("driving: speed, acceleration, yaw_rate, yaw_acceleration: expected > 0")
    rng = np.random.default_rng(seed)
    kinds, weights = zip(*MANOEUVRES)
    segs: list[Segment] = [alignment(np.zeros(2), np.zeros(2), pause=0.5, dt=dt)]
    pose, planned = np.zeros(3), segs[0].duration
    while planned < duration:
        kind = str(rng.choice(kinds, p=weights))
        new = _manoeuvre(kind, pose, geom, (length, width), rng, speed, acceleration, yaw_rate, yaw_acceleration,
                         margin, dt)
        pose = _end_pose(pose, new, geom, dt)
        pose[2] = round(pose[2] / (math.pi / 2)) * (math.pi / 2)  # axis directions up to round-off: snapped
        segs += new
        planned += sum(s.duration + dt for s in new)
    segs.append(alignment(np.zeros(2), np.zeros(2), pause=0.5, dt=dt))
    return Trajectory(tuple(segs), geom, dt, "driving")
