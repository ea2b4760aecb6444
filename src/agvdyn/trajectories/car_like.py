"""The car-like experiment: motion that determines B_w on the floor (``identify --fix none``).

In the car-like mode B_w's regressor column is a combination of those of m_ch, C_ch, C_l and C_r
up to one term: the yaw inertia the chassis shows. A wheel of inertia B_w rolling at the contact
offset ``a`` adds ``B_w / r^2`` to the mass of its contact point, so the yaw inertia of pure
rotation (mode 4) is ``C_ch + C_l + C_r + 238 B_w`` on the prototype, and the ``kappa^2``
coefficient of the chassis inertia of a car-like turn is ``C_ch + C_l + C_r + 218 B_w`` (plus
terms of higher order in the curvature kappa). B_w is their difference over about 20: both yaw
inertias are needed to ~0.07 kg m^2 (0.025 %) for a 3 % std of B_w. The experiment therefore has

* ``rotation``: pure rotation at the yaw-rate and yaw-acceleration limits (a sine at about
  2 rad/s, the rate of the two limits' ratio), which gives ``C_ch + C_l + C_r + 238 B_w``;
* ``lane_change`` (the label of car-like motion): tight turns with large yaw accelerations
  (Fourier series in ``(alpha_v, x_ch)`` around a turn, left then mirrored right), which give the
  car-like combination; the identification sequence (``identification``) gives the rest.

The coefficients were chosen on the prototype among random draws for the smallest predicted std of
B_w (:func:`agvdyn.trajectories.planner.evaluate_sequence` with ``estimate_bw=True``; see
docs/planning.md). Both segments are scaled to the limits, so another vehicle gets the same shapes.
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn.kinematics import Mode, max_virtual_angle, nominal_steering, steering_from_virtual
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME, Geometry, Parameters
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.limits import Limits, limit_report
from agvdyn.trajectories.segments import Segment, Trajectory, alignment, fourier_segment

__all__ = ["car_like_experiment", "ROTATION_SHAPE", "TURN_SHAPE"]

#: Rotation: base frequency (rad/s) and velocity coefficients (a, b) before the projection to rest;
#: the 8th harmonic (2 rad/s) dominates, the projection adds the ramp at both ends.
ROTATION_SHAPE = (0.25, (0.0,) * 7 + (1.0,) + (0.0,) * 4, (0.0,) * 12)
#: Car-like turns: period (s), peak alpha_v rate (rad/s), peak speed (m/s), and the velocity
#: coefficients (a, b) of alpha_v and of x_ch (the best of ~1100 random draws, centred at 0.373 rad).
TURN_SHAPE = (6.506, 1.087, 0.756,
              ((-0.396, 0.871, 0.126), (1.027, -0.278, 0.072)),
              ((-1.128, 0.329, -0.404), (1.285, -1.206, 0.426)))


def _scaled(series: FourierSeries, rate: float, acceleration: float, excursion: float) -> FourierSeries:
    """``series`` scaled to the first of a peak rate, acceleration and excursion it reaches."""
    q, qd, qdd = series.evaluate(np.linspace(0.0, series.period, 8001))
    f = min(rate / np.abs(qd).max(), acceleration / np.abs(qdd).max(), excursion / np.abs(q - series.start).max())
    return FourierSeries(series.base_frequency, tuple(np.array(series.a) * f), tuple(np.array(series.b) * f),
                         series.start)


def _turn_series(geom: Geometry, sign: float, centre: float, stop_margin: float
                 ) -> tuple[FourierSeries, FourierSeries]:
    """The series ``(alpha_v, x_ch)`` of the turns to the left (``sign`` 1) or right (-1)."""
    period, rate, speed, (a1, b1), (a2, b2) = TURN_SHAPE
    w = 2 * math.pi / period
    limit = stop_margin * max_virtual_angle(geom)
    c = min(centre, 0.5 * limit)
    sa = FourierSeries.at_rest(w, a1, b1, start=c, peak_velocity=rate, peak_excursion=limit - c)
    sx = FourierSeries.at_rest(w, a2, b2, peak_velocity=speed)
    return (FourierSeries(w, tuple(sign * x for x in sa.a), tuple(sign * x for x in sa.b), sign * c), sx)


def _scaled_by(series: FourierSeries, factor: float) -> FourierSeries:
    return FourierSeries(series.base_frequency, tuple(np.array(series.a) * factor),
                         tuple(np.array(series.b) * factor), series.start)


def car_like_experiment(geom: Geometry = PROTOTYPE, *, rotation_periods: int = 2, turn_periods: int = 5,
                        centre: float = 0.24, limits: Limits = Limits(), params: Parameters = PAPER_PARAMETERS,
                        margin: float = 0.9, max_heading: float = 1.6, stop_margin: float = 0.985,
                        pause: float = 0.5, dt: float = SAMPLE_TIME) -> Trajectory:
    """Car-like experiment for ``identify --fix none`` (B_w with the other ten, next to the
    identification sequence): ``rotation`` at ``margin`` of the yaw-rate and yaw-acceleration limits
    (``rotation_periods`` periods of 25.1 s, heading within ``max_heading`` rad), then car-like
    turns (segment ``lane_change``, ``turn_periods`` periods of 6.5 s to the left, as many mirrored
    to the right) that start at ``alpha_v = centre`` rad (at most half-way to the stops) and swing
    from there towards the stop, within ``stop_margin`` of it; alignments at rest between. The centre hardly changes the
    predicted std of B_w (2.8 % at 0 to 0.45 rad) but the bias that tyre compliance gives (on the
    simulator +32 % at 0, about 0 at 0.24, -42 % at 0.45): identify at two centres to see it.

    The turns' travel is scaled down until the planned motion (feed-forward with ``params``) keeps
    within ``margin`` of every limit. 2 + 5 periods: 127 s on the prototype.
    """
    if not (isinstance(rotation_periods, int) and isinstance(turn_periods, int)
            and rotation_periods >= 1 and turn_periods >= 1):
        raise TrajectoryError(f"car-like experiment: rotation_periods={rotation_periods!r}, "
                              f"turn_periods={turn_periods!r}: expected integers >= 1")
    if not (0 < margin <= 1 and 0 < stop_margin < 1):
        raise TrajectoryError(f"car-like experiment: margin={margin!r}, stop_margin={stop_margin!r}: "
                              "expected 0 < margin <= 1 and 0 < stop_margin < 1")
    w, a, b = ROTATION_SHAPE
    inside = 0.99 * margin  # the rotation just inside the margin the turns are checked against
    rot = _scaled(FourierSeries.at_rest(w, a, b), inside * limits.yaw_rate, inside * limits.yaw_acceleration,
                  max_heading)
    if not 0 <= centre < 1:
        raise TrajectoryError(f"car-like experiment: centre={centre!r}: expected an alpha_v in [0, 1) rad "
                              "(the turns swing from it towards the stop; the right turns mirror the left)")
    left, travel = _turn_series(geom, 1.0, centre, stop_margin)
    right = _turn_series(geom, -1.0, centre, stop_margin)[0]
    zero, spin = np.zeros(2), nominal_steering(geom, Mode.ROTATION)
    start_l, start_r = (steering_from_virtual(geom, np.array([s.start]))[0] for s in (left, right))
    kw = dict(pause=pause, dt=dt)
    for _ in range(8):  # scale the travel down until the turns keep within the limits
        turns = [fourier_segment("lane_change", Mode.CAR_LIKE, (s, travel), periods=turn_periods, geom=geom, dt=dt)
                 for s in (left, right)]
        segs: tuple[Segment, ...] = (
            alignment(zero, spin, **kw),
            fourier_segment("rotation", Mode.ROTATION, rot, periods=rotation_periods, geom=geom, dt=dt),
            alignment(spin, start_l, **kw), turns[0], alignment(start_l, start_r, **kw), turns[1],
            alignment(start_r, zero, **kw))
        traj = Trajectory(segs, geom, dt, "car_like")
        report = limit_report(traj, params, limits)
        worst = min(margin * report.limits[k] / report.peaks[k] for k in report.peaks if report.peaks[k] > 0)
        if worst >= 1:
            return traj
        travel = _scaled_by(travel, worst * 0.99)
    raise TrajectoryError(f"car-like experiment: the turns do not fit within {margin:g} of the limits "
                          f"({report.peaks}): expected wider limits")
