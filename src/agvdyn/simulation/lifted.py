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

import math
from collections.abc import Callable

import numpy as np

from agvdyn.platform import Geometry, Parameters
from agvdyn.simulation._kernels import run_lifted_chunk
from agvdyn.simulation.plant import plant_constants
from agvdyn.simulation.sensors import draw_noise
from agvdyn.trajectories import Trajectory, check_limits

__all__ = ["simulate_lifted"]

#: Samples simulated between two progress reports.
CHUNK = 5000


def simulate_lifted(traj: Trajectory, platform: Geometry, plant_params: Parameters, controller_params: Parameters,
                    settings, seed: int, progress: Callable[[int, int], None] | None = None):
    """Simulate a lifted-wheel trajectory (``traj.lifted``); returns a :class:`SimulationResult`."""
    from dataclasses import replace

    from agvdyn.simulation import SimulationResult

    if settings.slip.active:
        raise ValueError("a slip scenario needs ground contact: the lifted-wheel experiment has none")
    Ts = settings.sample_time
    motion = traj.joint_motion()
    q_dot_d = motion[0]
    u_ff = np.ascontiguousarray(traj.feedforward(controller_params))
    if settings.check_limits:
        limits = settings.limits
        if settings.plant.torque_limit is not None and settings.plant.torque_limit != limits.motor_torque:
            limits = replace(limits, motor_torque=settings.plant.torque_limit)
        check_limits(traj, controller_params, limits, motion=motion, torques=u_ff)
    beta_d = np.ascontiguousarray(traj.wheel_angles(q_dot_d))
    beta_dot_d = np.ascontiguousarray(q_dot_d[:, 5:])
    n = traj.n_samples
    noise = draw_noise(n, settings.sensors, np.random.default_rng(seed))
    c = plant_constants(platform, plant_params, settings.plant)
    g = settings.controller.gains(platform)
    wheel_res = 2 * math.pi / (settings.sensors.encoder_counts * platform.i_G)
    steer_res = 2 * math.pi / settings.sensors.steering_counts
    pos = np.zeros(9)
    pos[3:5] = traj.alpha[0]
    vel = np.zeros(9)
    cstate = np.zeros(13)
    work = np.zeros(3)
    out = {k: np.zeros((n, w)) for k, w in (("pos", 9), ("vel", 9), ("alpha", 2), ("beta", 4), ("cmd", 4),
                                            ("app", 4), ("meas", 4), ("work", 3))}
    energy = np.zeros(n)
    for k0 in range(0, n, CHUNK):
        k1 = min(n, k0 + CHUNK)
        run_lifted_chunk(k0, k1, c, g, Ts, settings.plant.substeps, wheel_res, steer_res, u_ff, beta_d, beta_dot_d,
                         noise.steering, noise.torque, noise.torque_offset, pos, vel, cstate, work,
                         out["pos"], out["vel"], out["alpha"], out["beta"], out["cmd"], out["app"], out["meas"],
                         energy, out["work"])
        if not np.all(np.isfinite(vel)):
            raise FloatingPointError(f"simulation of {traj.name!r} diverged at t = {k1 * Ts:.3f} s")
        if progress is not None:
            progress(k1, n)
    return SimulationResult(
        traj, platform, plant_params, controller_params, settings, seed,
        out["pos"], out["vel"], q_dot_d, beta_d, u_ff, out["alpha"], out["beta"],
        out["cmd"], out["app"], out["meas"], energy, out["work"], np.zeros((n, 4)), lifted=True,
    )
