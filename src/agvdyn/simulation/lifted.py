"""The single-axis experiment of sec. 7: the vehicle on jacks, the wheels turning without ground contact.

The paper takes the motor-gear-wheel inertia ``B_w`` from such a test and fixes it (sec. 6.3).
Here the chassis and the steering stand still and each wheel obeys the wheel row of eq. (16)-(17),
``B_w beta_ddot + d_vw beta_dot + F_c(beta_dot) = i_G M``, with the plant's Coulomb friction
(stiction by default) and the same linearly-implicit step as the plant. The drive applies the
feed-forward torque sequence of the planned wheel motion (with the controller's parameters) plus
the wheel speed loops of the controller, one per wheel (the loops on the vehicle act on a side's
mean because there the front-rear difference is the steering; here every wheel is free); the
sensors are those of the vehicle (encoders, torque noise and offsets, noisy steering angles).
The log's segment label is ``lifted_wheel``.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from agvdyn.platform import Geometry, Parameters
from agvdyn.simulation._lifted_kernels import run_lifted_chunk
from agvdyn.simulation._setup import prepare_run, run_chunks
from agvdyn.simulation.result import SimulationResult
from agvdyn.trajectories import Trajectory

__all__ = ["simulate_lifted"]

#: Size of the controller state of the lifted-wheel kernel (``_lifted_kernels.run_lifted_chunk``).
LIFTED_STATE_SIZE = 13


def simulate_lifted(traj: Trajectory, platform: Geometry, plant_params: Parameters, controller_params: Parameters,
                    settings, seed: int, progress: Callable[[int, int], None] | None = None):
    """Simulate a lifted-wheel trajectory (``traj.lifted``); returns a :class:`SimulationResult`."""
    if settings.slip.active:
        raise ValueError("a slip scenario needs ground contact: the lifted-wheel experiment has none")
    Ts = settings.sample_time
    st = prepare_run(traj, platform, plant_params, controller_params, settings, seed, LIFTED_STATE_SIZE)
    out = st.out
    beta_dot_d = np.ascontiguousarray(st.q_dot_d[:, 5:])
    n = traj.n_samples

    def step(k0: int, k1: int) -> None:
        run_lifted_chunk(k0, k1, st.c, st.g, Ts, settings.plant.substeps, st.wheel_res, st.steer_res, st.u_ff,
                         st.beta_d, beta_dot_d, st.noise.steering, st.noise.torque, st.noise.torque_offset, st.pos,
                         st.vel, st.cstate, st.work, out["pos"], out["vel"], out["alpha"], out["beta"], out["cmd"],
                         out["app"], out["meas"], st.energy, out["work"])

    run_chunks(traj.name, n, Ts, st, step, progress)
    return SimulationResult(
        traj, platform, plant_params, controller_params, settings, seed,
        out["pos"], out["vel"], st.q_dot_d, st.beta_d, st.u_ff, out["alpha"], out["beta"],
        out["cmd"], out["app"], out["meas"], st.energy, out["work"], np.zeros((n, 4)), lifted=True,
    )
