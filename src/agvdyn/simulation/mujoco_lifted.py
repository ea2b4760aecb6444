"""The lifted-wheel experiment (sec. 7) on MuJoCo: the vehicle on jacks, its wheels turning freely.

The MuJoCo vehicle (:class:`~agvdyn.simulation.mujoco_plant.MujocoVehicle`) with its chassis welded
to the world high above the floor (the free joint removed, :func:`lifted_model`): no contact, the
steering units standing on their passive hinges, each wheel turned by its motor against MuJoCo's
joint damping, frictionloss (dry friction) and armature. The drive and sensors are those of our
plant's lifted-wheel run (:func:`agvdyn.simulation._lifted_kernels.lifted_drive_sample`: the
feed-forward plus a speed loop per wheel), so both engines run the same experiment.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from agvdyn.platform import WHEELS, Parameters
from agvdyn.simulation._lifted_kernels import lifted_drive_sample
from agvdyn.simulation._setup import prepare_run, run_chunks
from agvdyn.simulation.mujoco_plant import MujocoVehicle, _id, _mujoco, sample_substeps
from agvdyn.simulation.result import SimulationResult

__all__ = ["lifted_model", "simulate_lifted_mujoco", "LIFT_HEIGHT"]

#: Height (m) of the chassis frame above the floor on the jacks: far above any wheel.
LIFT_HEIGHT = 1.0


def lifted_model(vehicle: MujocoVehicle):
    """The compiled MuJoCo model of ``vehicle`` on jacks: its chassis fixed ``LIFT_HEIGHT`` m above
    the floor (the free joint ``root`` removed), everything else as in the MJCF."""
    mujoco = _mujoco()
    source = str(vehicle.source or "generated MJCF")
    spec = mujoco.MjSpec.from_string(vehicle.xml)
    chassis = spec.body("chassis")
    if chassis is None:
        raise ValueError(f"{source}: no body named 'chassis': expected agvdyn's vehicle model")
    free = [j for j in chassis.joints if j.type == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise ValueError(f"{source}: the chassis has {len(free)} free joints: expected one ('root')")
    spec.delete(free[0])
    chassis.pos = [0.0, 0.0, LIFT_HEIGHT + vehicle.geometry.r]
    return spec.compile()


def simulate_lifted_mujoco(traj, vehicle: MujocoVehicle, controller_params: Parameters, settings, seed: int,
                           progress: Callable[[int, int], None] | None = None) -> SimulationResult:
    """Simulate a lifted-wheel trajectory (``traj.lifted``) on MuJoCo; returns a :class:`SimulationResult`
    (engine ``"mujoco"``; kinetic energy of the wheels and units from MuJoCo, dissipated work = motor
    work - change of kinetic energy)."""
    from agvdyn.simulation.lifted import LIFTED_STATE_SIZE

    if settings.slip.active:
        raise ValueError("a slip scenario needs ground contact: the lifted-wheel experiment has none")
    mujoco = _mujoco()
    model = lifted_model(vehicle)
    data = mujoco.MjData(model)
    Ts = settings.sample_time
    substeps = sample_substeps(model, Ts)
    src = str(vehicle.source or "generated MJCF")
    steer = [int(model.jnt_qposadr[_id(model, "joint", f"steer_{w}", src)]) for w in ("fl", "fr")]
    steer_v = [int(model.jnt_dofadr[_id(model, "joint", f"steer_{w}", src)]) for w in ("fl", "fr")]
    wheel = [int(model.jnt_qposadr[_id(model, "joint", f"wheel_{w}", src)]) for w in WHEELS]
    wheel_v = [int(model.jnt_dofadr[_id(model, "joint", f"wheel_{w}", src)]) for w in WHEELS]
    motors = [_id(model, "actuator", f"motor_{w}", src) for w in WHEELS]
    params = vehicle.parameters
    st = prepare_run(traj, vehicle.geometry, params, controller_params, settings, seed, LIFTED_STATE_SIZE)
    _start_on_jacks(model, data, traj.alpha[0], steer)
    out, n = st.out, traj.n_samples
    energy = np.zeros(n)
    alpha_m, beta_m, u, ua = np.zeros(2), np.zeros(4), np.zeros(4), np.zeros(4)
    i_G = float(vehicle.geometry.i_G)
    beta_dot_d = np.ascontiguousarray(st.q_dot_d[:, 5:])

    def step(k0: int, k1: int) -> None:
        for k in range(k0, k1):
            st.pos[3:5] = data.qpos[steer]
            st.vel[3:5] = data.qvel[steer_v]
            st.pos[5:] = data.qpos[wheel]
            st.vel[5:] = data.qvel[wheel_v]
            lifted_drive_sample(k, st.c, st.g, Ts, st.wheel_res, st.steer_res, st.u_ff, st.beta_d,
                                beta_dot_d, st.noise.steering, st.noise.torque,
                                st.noise.torque_offset, st.pos, st.vel, st.cstate, st.work, alpha_m, beta_m, u, ua,
                                out["pos"], out["vel"], out["alpha"], out["beta"], out["cmd"], out["app"],
                                out["meas"], out["work"])
            data.ctrl[motors] = ua
            st.work[0] += Ts * i_G * float(ua @ st.vel[5:])
            mujoco.mj_step(model, data)
            energy[k] = data.energy[1]
            if substeps > 1:
                mujoco.mj_step(model, data, substeps - 1)

    run_chunks(traj.name, n, Ts, st, step, progress)
    out["work"][:, 1] = out["work"][:, 0] - (energy - energy[0])
    return SimulationResult(
        traj, vehicle.geometry, params, controller_params, settings, seed,
        out["pos"], out["vel"], st.q_dot_d, st.beta_d, st.u_ff, out["alpha"], out["beta"],
        out["cmd"], out["app"], out["meas"], energy, out["work"], np.zeros((n, 4)), lifted=True,
        engine="mujoco", vehicle=vehicle,
    )


def _start_on_jacks(model, data, alpha0, steer: list[int]) -> None:
    """At rest with the steering at ``alpha0`` (left and right; the rear units follow the coupling)."""
    mujoco = _mujoco()
    mujoco.mj_resetData(model, data)
    src = "model"
    for i, w in enumerate(WHEELS):
        q = model.jnt_qposadr[_id(model, "joint", f"steer_{w}", src)]
        data.qpos[q] = (alpha0[0] if i < 2 else alpha0[1]) * (1.0 if i % 2 == 0 else -1.0)
    mujoco.mj_forward(model, data)
