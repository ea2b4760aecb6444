"""Built-in experiments: the identification sequence of sec. 6.2 with its default excitation, the
lane change of sec. 7 (validation), the lateral experiment, the lifted-wheel (single-axis) test of
sec. 7; the car-like experiment for B_w on the floor is in :mod:`agvdyn.trajectories.car_like`, and
:func:`~agvdyn.trajectories.catalog.experiment` (any of them by name, or a file) in :mod:`.catalog`."""
from __future__ import annotations

import math

import numpy as np

from agvdyn.kinematics import Mode, max_virtual_angle, nominal_steering, steering_from_virtual
from agvdyn.platform import PROTOTYPE, SAMPLE_TIME, Geometry
from agvdyn.trajectories.errors import LimitError, TrajectoryError
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.segments import (
    _SMOOTH_PEAK_V,
    Segment,
    Trajectory,
    _grid,
    _smoothstep,
    alignment,
    fourier_segment,
)

__all__ = ["default_excitation", "default_periods", "identification_sequence", "lateral_experiment", "lane_change",
           "lifted_wheel_experiment", "EXPERIMENTS"]

#: Names of the built-in experiments of :func:`agvdyn.trajectories.catalog.experiment`.
EXPERIMENTS = ("identification", "lane-change", "lateral", "lifted-wheel", "car-like", "driving")


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
                            pause: float = 0.5, dt: float = SAMPLE_TIME, align_rate: float = 0.8,
                            align_acceleration: float = 2.0) -> Trajectory:
    """Identification sequence of sec. 6.2: steer_left, steer_right, straight, rotation.

    Mode 1 with one side held at zero, straight motion (mode 2, alpha_v = 0), pure rotation
    (mode 4), with ``align`` segments at rest between them (a ``pause`` when the wheels need not
    turn; before the rotation the wheels turn to arctan(l/b) (-1, 1) and back to zero after it).
    The steering series run ``steering_periods`` periods (default: 3 with the default series, else 1).
    ``align_rate``, ``align_acceleration``: peak steering rate and acceleration of the alignments.
    """
    periods = steering_periods or (default_periods("steer_left") if steer_left is None and steer_right is None else 1)
    sl = steer_left or default_excitation("steer_left")
    sr = steer_right or default_excitation("steer_right")
    zero2 = np.zeros(2)
    rot = nominal_steering(geom, Mode.ROTATION)
    kw = dict(pause=pause, dt=dt, rate=align_rate, acceleration=align_acceleration)
    segs = [
        alignment(zero2, zero2, **kw),
        fourier_segment("steer_left", Mode.PARKING, (sl, _zero_series(sl)), periods=periods, geom=geom, dt=dt),
        alignment(zero2, zero2, **kw),
        fourier_segment("steer_right", Mode.PARKING, (_zero_series(sr), sr), periods=periods, geom=geom, dt=dt),
        alignment(zero2, zero2, **kw),
        fourier_segment("straight", Mode.STRAIGHT, straight or default_excitation("straight"), geom=geom, dt=dt),
        alignment(zero2, rot, **kw),
        fourier_segment("rotation", Mode.ROTATION, rotation or default_excitation("rotation"), geom=geom, dt=dt),
        alignment(rot, zero2, **kw),
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
    from scipy.optimize import brentq  # here: scipy.optimize is ~0.3 s of start-up the other experiments never use

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


def _envelope(t: np.ndarray, edges: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Smooth direction envelope 0 -> +1 -> -1 -> 0 (quintic steps between the times ``edges``,
    pairs (start, end) of each step) and its time derivative."""
    levels = (0.0, 1.0, -1.0, 0.0)
    e, de = np.zeros_like(t), np.zeros_like(t)
    for k, (a, b) in enumerate(zip(edges[0::2], edges[1::2])):
        p, pd_, _ = _smoothstep((t - a) / (b - a))
        jump = levels[k + 1] - levels[k]
        e += jump * p
        de += jump * pd_ * ((t > a) & (t < b)) / (b - a)
    return e, de


def lifted_wheel_experiment(geom: Geometry = PROTOTYPE, *, duration: float = 24.0, mean_speed: float = 10.0,
                            amplitude: float = 7.0, frequencies: tuple[float, ...] = (2.0, 4.7, 8.3),
                            weights: tuple[float, ...] = (0.5, 0.3, 0.2), ramp: float = 1.5, reversal: float = 2.0,
                            pause: float = 0.5, dt: float = SAMPLE_TIME) -> Trajectory:
    """Single-axis experiment of sec. 7 (segment ``lifted_wheel``): the vehicle on jacks, each wheel
    driven without ground contact, for ``B_w`` (and the wheel friction without load).

    Each wheel turns forward, then backward: its rate is ``E(t) m_i(t)`` with a smooth direction
    envelope E (0 -> +1 in ``ramp`` s, +1 -> -1 in ``reversal`` s at mid-time, -1 -> 0) and a speed
    ``m_i = mean_speed + amplitude sum_k weights_k sin(frequencies_k t + phi_ik)`` (rad/s, wheel
    side; phases differ per wheel), which keeps the wheels away from standstill except at the
    start, the reversal and the end: only three stick events, while the accelerations
    (``B_w beta_ddot``) change all the time. Both directions separate Coulomb friction from a
    motor-torque offset. ``pause`` s at rest before and after.
    """
    if not (duration > 2 * (pause + ramp) + reversal and mean_speed > amplitude * sum(weights) >= 0):
        raise TrajectoryError(f"lifted wheel: duration={duration}, mean_speed={mean_speed}, amplitude={amplitude}: "
                              "expected a duration longer than the pauses, ramps and reversal and "
                              "mean_speed > amplitude * sum(weights) (the wheels keep turning one way)")
    if len(frequencies) != len(weights):
        raise TrajectoryError(f"lifted wheel: {len(frequencies)} frequencies and {len(weights)} weights: "
                              "expected as many of each")
    t = _grid(duration, dt)
    T = t[-1]
    mid = T / 2
    edges = (pause, pause + ramp, mid - reversal / 2, mid + reversal / 2, T - pause - ramp, T - pause)
    e, de = _envelope(t, edges)
    golden = (math.sqrt(5) - 1) / 2
    rates = np.zeros((t.size, 2, 4))
    for i in range(4):
        m, dm = np.full_like(t, mean_speed), np.zeros_like(t)
        for k, (w, c) in enumerate(zip(frequencies, weights)):
            phi = 2 * math.pi * ((golden * (i + 1) * (k + 1)) % 1.0)
            m += amplitude * c * np.sin(w * t + phi)
            dm += amplitude * c * w * np.cos(w * t + phi)
        rates[:, 0, i] = e * m
        rates[:, 1, i] = de * m + e * dm
    zeros = np.zeros((t.size, 2))
    seg = Segment("lifted_wheel", Mode.PARKING, t, zeros, zeros, zeros, zeros, wheel_rates=rates)
    return Trajectory((seg,), geom, dt, "lifted_wheel")
