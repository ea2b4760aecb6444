"""What every closed-loop run starts from, and its chunked stepping (shared by the ground and the
lifted-wheel simulations, on either engine); after the last chunk the torque sensors' delay
(``SensorSettings.torque_delay``) is applied to the logged torques."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from agvdyn.platform import Geometry, Parameters
from agvdyn.simulation.plant import plant_constants
from agvdyn.simulation.sensors import delayed_torques, draw_noise
from agvdyn.trajectories import Trajectory, check_limits

#: Samples simulated between two progress reports.
CHUNK = 5000


@dataclass(eq=False)
class RunState:
    """The plan (joint motion, feed-forward of eq. 21, wheel angles), sensor noise, compiled plant
    constants and controller gains, encoder resolutions, the mutable plant and controller state,
    the output buffers of one run and the lag of the logged torques in sample periods."""

    q_dot_d: np.ndarray
    u_ff: np.ndarray
    beta_d: np.ndarray
    noise: Any
    c: np.ndarray
    g: np.ndarray
    wheel_res: float
    steer_res: float
    pos: np.ndarray
    vel: np.ndarray
    cstate: np.ndarray
    work: np.ndarray
    out: dict[str, np.ndarray]
    energy: np.ndarray
    torque_delay_samples: float = 0.0


def desired_motion(traj: Trajectory, st: RunState) -> tuple[np.ndarray, ...]:
    """The set points of the controller as contiguous arrays: ``alpha_d`` (N, 2), ``mode_d`` (N,),
    ``alpha_dot_d`` (N, 2), ``beta_dot_d`` (N, 4) and the sample times ``t`` (N,)."""
    return (np.ascontiguousarray(traj.alpha), np.ascontiguousarray(traj.mode, dtype=np.int64),
            np.ascontiguousarray(st.q_dot_d[:, 3:5]), np.ascontiguousarray(st.q_dot_d[:, 5:]),
            np.ascontiguousarray(traj.t, dtype=float))


def prepare_run(traj: Trajectory, platform: Geometry, plant_params: Parameters, ctrl_params: Parameters,
                settings: Any, seed: int, state_size: int) -> RunState:
    """Plan, check the limits (``settings.check_limits``), draw the noise and set up the state."""
    motion = traj.joint_motion()
    q_dot_d = motion[0]
    u_ff = np.ascontiguousarray(traj.feedforward(ctrl_params, motion))
    if settings.check_limits:
        limits = settings.limits
        if settings.plant.torque_limit is not None and settings.plant.torque_limit != limits.motor_torque:
            limits = replace(limits, motor_torque=settings.plant.torque_limit)
        check_limits(traj, ctrl_params, limits, motion=motion, torques=u_ff)
    n = traj.n_samples
    pos = np.zeros(9)
    pos[3:5] = traj.alpha[0]
    out = {k: np.zeros((n, w)) for k, w in (("pos", 9), ("vel", 9), ("alpha", 2), ("beta", 4), ("cmd", 4),
                                            ("app", 4), ("meas", 4), ("work", 3))}
    return RunState(
        q_dot_d, u_ff, np.ascontiguousarray(traj.wheel_angles(q_dot_d)),
        draw_noise(n, settings.sensors, np.random.default_rng(seed)),
        plant_constants(platform, plant_params, settings.plant), settings.controller.gains(platform),
        2 * math.pi / (settings.sensors.encoder_counts * platform.i_G), 2 * math.pi / settings.sensors.steering_counts,
        pos, np.zeros(9), np.zeros(state_size), np.zeros(3), out, np.zeros(n),
        settings.sensors.torque_delay / settings.sample_time)


def run_chunks(name: str, n: int, sample_time: float, state: RunState, step: Callable[[int, int], None],
               progress: Callable[[int, int], None] | None) -> None:
    """Call ``step(k0, k1)`` over the samples in chunks, checking for divergence and reporting progress;
    then delay the measured torques ``state.out["meas"]`` by ``state.torque_delay_samples`` (in place;
    nothing is done without a delay)."""
    for k0 in range(0, n, CHUNK):
        k1 = min(n, k0 + CHUNK)
        step(k0, k1)
        if not np.all(np.isfinite(state.pos)) or not np.all(np.isfinite(state.vel)):
            raise FloatingPointError(f"simulation of {name!r} diverged at t = {k1 * sample_time:.3f} s: "
                                     "reduce the plant step (substeps) or the gains")
        if progress is not None:
            progress(k1, n)
    if state.torque_delay_samples > 0:
        state.out["meas"][:] = delayed_torques(state.out["meas"], state.torque_delay_samples)
