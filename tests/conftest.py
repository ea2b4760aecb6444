"""Shared strategies for property tests of the model."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import strategies as st

from agvdyn.kinematics import Mode, max_virtual_angle, nominal_steering, steering_from_virtual
from agvdyn.platform import Geometry

geometries = st.builds(
    Geometry,
    l=st.floats(0.4, 3.0),
    b=st.floats(0.4, 2.0),
    a=st.floats(-0.15, 0.15).filter(lambda a: abs(a) > 1e-3),
    r=st.floats(0.05, 0.4),
    i_G=st.floats(1.0, 100.0),
)
modes = st.sampled_from(list(Mode))


def configurations(geom: Geometry, mode: Mode, n: int, rng: np.random.Generator) -> np.ndarray:
    """Random steering angles (n, 2) in the given mode."""
    if mode is Mode.PARKING:
        return rng.uniform(-np.pi / 2, np.pi / 2, (n, 2))
    if mode is Mode.CAR_LIKE:
        return steering_from_virtual(geom, rng.uniform(-0.97, 0.97, n) * max_virtual_angle(geom))
    return np.tile(nominal_steering(geom, mode), (n, 1))


@pytest.fixture(scope="session")
def short_sequence():
    """The identification sequence with 4-5 s segments (the default one lasts 118 s): the simulator's tests."""
    import math

    from agvdyn.trajectories import FourierSeries, identification_sequence

    def series(period: float, peak: float) -> FourierSeries:
        return FourierSeries.at_rest(2 * math.pi / period, (1.0, -0.5, 0.3), (0.2, 0.5, -0.4), peak_velocity=peak)

    return identification_sequence(steer_left=series(4, 1.2), steer_right=series(4, 1.2),
                                   straight=series(5, 0.4), rotation=series(5, 0.5), pause=0.2)
