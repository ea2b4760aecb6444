"""Planned motions: Fourier excitation (sec. 6.2), the identification sequence, the lane change
of sec. 7, the lateral and lifted-wheel experiments, user trajectories read from files, and the
planner of optimal identification sequences in limited floor space.

One module per job, data flowing one way::

    errors       TrajectoryError, LimitError
    fourier      FourierSeries: finite Fourier series starting and ending at rest
    segments     Segment, Trajectory, alignment at rest, Fourier segments, FloorSpace and
                 floor_space (the floor a trajectory occupies)
    limits       Limits, limit_report, check_limits
    experiments  default excitation, identification sequence, lane change, lateral, lifted wheel
    car_like     the car-like experiment: fast rotation and tight turns for B_w (identify --fix none)
    driving      the driving experiment: a warehouse shift (payload tracking, issue 31)
    files        read_trajectory (CSV / YAML), write_trajectory (YAML)
    catalog      experiment(name): a built-in experiment by name, or a trajectory file
    planner      plan(): optimal four-phase identification sequence in a floor rectangle

Generalized coordinates per mode (PLATFORM.md): mode 1 ``(alpha_l, alpha_r)``, mode 2
``(alpha_v, x_ch)``, mode 3 ``y_ch``, mode 4 ``gamma_ch``, straight ``x_ch``; ``x_ch`` and
``y_ch`` are distances travelled along the chassis axes (integrals of ``v_x``, ``v_y``).
Every public name is importable from ``agvdyn.trajectories``.
"""
from agvdyn.trajectories.errors import LimitError, TrajectoryError
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.segments import (
    CONTINUITY_TOLERANCE,
    SEGMENT_NAMES,
    Segment,
    Trajectory,
    alignment,
    fourier_segment,
    pose_from_velocities,
)
from agvdyn.trajectories.limits import FloorSpace, LimitReport, Limits, check_limits, floor_space, limit_report
from agvdyn.trajectories.experiments import (
    EXPERIMENTS,
    default_excitation,
    default_periods,
    identification_sequence,
    lane_change,
    lateral_experiment,
    lifted_wheel_experiment,
)
from agvdyn.trajectories.car_like import car_like_experiment
from agvdyn.trajectories.driving import driving_experiment
from agvdyn.trajectories.files import read_trajectory
from agvdyn.trajectories.catalog import experiment

__all__ = [
    "TrajectoryError", "LimitError", "FourierSeries", "CONTINUITY_TOLERANCE", "SEGMENT_NAMES", "Segment",
    "Trajectory", "alignment", "fourier_segment", "pose_from_velocities", "FloorSpace", "LimitReport", "Limits",
    "check_limits", "floor_space", "limit_report", "default_excitation", "default_periods", "experiment",
    "identification_sequence", "lane_change", "lateral_experiment", "lifted_wheel_experiment", "EXPERIMENTS",
    "car_like_experiment", "driving_experiment", "read_trajectory",
]
