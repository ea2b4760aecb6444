"""Any experiment by name: the built-in ones (:mod:`.experiments`, :mod:`.car_like`) or a trajectory
file (:mod:`.files`). Above both, so that neither imports the other's module back."""
from __future__ import annotations

from pathlib import Path

from agvdyn.platform import PROTOTYPE, SAMPLE_TIME, Geometry
from agvdyn.trajectories.car_like import car_like_experiment
from agvdyn.trajectories.driving import driving_experiment
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import (
    EXPERIMENTS,
    identification_sequence,
    lane_change,
    lateral_experiment,
    lifted_wheel_experiment,
)
from agvdyn.trajectories.files import read_trajectory
from agvdyn.trajectories.segments import Trajectory

__all__ = ["experiment"]


def experiment(name: str, geom: Geometry = PROTOTYPE, *, dt: float = SAMPLE_TIME, **options) -> Trajectory:
    """Built-in experiment by name (``identification``, ``lane-change``, ``lateral``, ``lifted-wheel``,
    ``car-like``, ``driving``) or a trajectory file. ``options``: keywords of ``driving``
    (:func:`~agvdyn.trajectories.driving.driving_experiment`: ``duration``, ``floor``, ``seed``, ...)."""
    key = name.strip().lower().replace("_", "-")
    if key == "driving":
        return driving_experiment(geom, dt=dt, **options)
    if options:
        raise TrajectoryError(f"experiment {name!r} takes no options {sorted(options)}: only 'driving' does")
    if key == "identification":
        return identification_sequence(geom, dt=dt)
    if key == "lane-change":
        return lane_change(geom, dt=dt)
    if key == "lateral":
        return lateral_experiment(geom, dt=dt)
    if key == "lifted-wheel":
        return lifted_wheel_experiment(geom, dt=dt)
    if key == "car-like":
        return car_like_experiment(geom, dt=dt)
    if Path(name).suffix.lower() in (".csv", ".yaml", ".yml"):
        return read_trajectory(name, geom, dt=dt)
    raise TrajectoryError(f"unknown experiment {name!r}: expected one of {', '.join(EXPERIMENTS)} "
                          "or a trajectory file (.csv, .yaml)")
