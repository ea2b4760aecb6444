"""Closed-loop simulation of the vehicle: plant with tyre slip, drive controller, sensors, logs.

Entry point :func:`simulate` returns a :class:`SimulationResult` (true states, commanded and
measured signals, tracking errors, the log in the PLATFORM.md schema); :func:`feedforward_table`
gives the planned trajectory with its feed-forward motor torques of eq. (21).

Example
-------
>>> from agvdyn.simulation import simulate
>>> result = simulate("identification", seed=1)          # doctest: +SKIP
>>> result.write("identification.parquet")               # doctest: +SKIP
"""
from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
from agvdyn._lazy import pandas as pd  # tables only (feedforward_table, the frames): simulating and writing a log need no pandas

from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME, WHEELS, Geometry, Parameters
from agvdyn.simulation._kernels import run_chunk
from agvdyn.simulation.controller import STATE_SIZE, ControllerSettings
from agvdyn.simulation._setup import desired_motion, prepare_run, run_chunks
from agvdyn.simulation.plant import PlantSettings, plant_constants, run_open_loop
from agvdyn.simulation.result import SimulationResult
from agvdyn.simulation.sensors import SensorSettings
from agvdyn.simulation.settings import SimulationSettings, read_settings, settings_from_dict
from agvdyn.simulation.slip import (
    SLIP_SCENARIO,
    SLIP_THRESHOLD,
    FrictionPatch,
    SlipInterval,
    SlipSettings,
    TorqueBurst,
)
from agvdyn.trajectories import (
    Limits,
    Trajectory,
    TrajectoryError,
    check_limits,
    experiment as build_experiment,
)

__all__ = [
    "ControllerSettings", "PlantSettings", "SensorSettings", "SimulationSettings", "SimulationResult",
    "simulate", "feedforward_table", "run_open_loop", "plant_constants", "read_settings", "settings_from_dict",
    "SlipSettings", "FrictionPatch", "TorqueBurst", "SlipInterval", "SLIP_SCENARIO", "SLIP_THRESHOLD",
]



def _trajectory(experiment: str | os.PathLike | Trajectory, geom: Geometry, dt: float) -> Trajectory:
    if isinstance(experiment, Trajectory):
        planned = {k: v for k, v in experiment.geometry.to_dict().items() if k != "name"}
        given = {k: v for k, v in geom.to_dict().items() if k != "name"}
        if planned != given:
            raise ValueError(f"trajectory planned for the platform {planned} but used on {given}: "
                             "plan it with the same geometry")
        if abs(experiment.sample_time - dt) > 1e-12:
            raise ValueError(f"trajectory sampled at {experiment.sample_time} s, expected {dt} s")
        return experiment
    return build_experiment(str(experiment), geom, dt=dt)


def simulate(
    experiment: str | os.PathLike | Trajectory,
    *,
    platform: Geometry = PROTOTYPE,
    plant_params: Parameters = PAPER_PARAMETERS,
    controller_params: Parameters | None = None,
    settings: SimulationSettings = SimulationSettings(),
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    engine: str = "ours",
    mjcf: str | os.PathLike | None = None,
    split: Any = None,
    engine_options: Any = None,
) -> SimulationResult:
    """Simulate an experiment in closed loop and record what the vehicle's sensors see.

    Parameters
    ----------
    experiment : ``"identification"``, ``"lane-change"``, ``"lateral"``, a trajectory file
        (.csv/.yaml, see :func:`agvdyn.trajectories.read_trajectory`) or a :class:`Trajectory`.
    platform : geometry of plant and controller.
    plant_params : the true parameters of the simulated vehicle (eq. 18 order).
    controller_params : the controller's estimate for the feed-forward of eq. (21); default: the true ones.
    settings : plant, controller, sensor and limit settings.
    seed : seed of ``numpy.random.default_rng`` for all sensor noise; equal seeds give equal logs.
    progress : called as ``progress(samples_done, samples_total)`` between chunks.
    engine : the plant: ``"ours"`` (plant.py, tyre slip) or ``"mujoco"`` (mujoco_plant.py, generated
        from ``platform`` and ``plant_params`` with ``split`` (mujoco_model.BodySplit) and ``engine_options``
        (mujoco_model.EngineOptions; default wheel radii from ``settings.plant.wheel_radius_error``)).
    mjcf : with ``engine="mujoco"``: run this MJCF file instead; its geometry and lumped parameters
        replace ``platform`` and ``plant_params`` (which must then be left at their defaults).

    Raises
    ------
    LimitError : the planned trajectory breaks a limit (with ``settings.check_limits``).
    """
    Ts = settings.sample_time
    vehicle = None
    if engine not in ENGINES:
        raise ValueError(f"engine={engine!r}: expected one of {ENGINES}")
    if engine == "mujoco":
        vehicle, platform, plant_params, settings = _mujoco_vehicle(platform, plant_params, settings, mjcf, split,
                                                                    engine_options)
    elif mjcf is not None or split is not None or engine_options is not None:
        raise ValueError("mjcf, split and engine_options belong to engine='mujoco'")
    traj = _trajectory(experiment, platform, Ts)
    ctrl_params = plant_params if controller_params is None else controller_params
    if traj.lifted and settings.payload:
        raise ValueError(f"experiment {traj.name!r}: payload events need the vehicle on the ground")
    if traj.lifted and vehicle is not None and any(r != 1.0 for r, _ in settings.plant.group_breakaway()):
        raise ValueError(f"experiment {traj.name!r} on MuJoCo: breakaway friction runs on the driving MuJoCo plant "
                         "only (mujoco_friction.py), the lifted one has MuJoCo's dry friction: use engine='ours' "
                         "or no breakaway")
    if traj.lifted and vehicle is not None:  # sec. 7 on MuJoCo: the chassis welded above the floor
        from agvdyn.simulation.mujoco_lifted import simulate_lifted_mujoco

        return simulate_lifted_mujoco(traj, vehicle, ctrl_params, settings, seed, progress)
    if traj.lifted:  # the single-axis experiment of sec. 7 (lifted.py)
        from agvdyn.simulation.lifted import simulate_lifted

        return simulate_lifted(traj, platform, plant_params, ctrl_params, settings, seed, progress)
    st = prepare_run(traj, platform, plant_params, ctrl_params, settings, seed, STATE_SIZE)
    out = st.out
    alpha_d, mode_d, alpha_dot_d, beta_dot_d, t = desired_motion(traj, st)
    burst = settings.slip.burst_torques(t)
    patches = settings.slip.patch_table()

    def step(k0: int, k1: int) -> None:  # our plant; MuJoCo's: mujoco_plant.mujoco_stepper
        run_chunk(k0, k1, st.c, st.g, Ts, settings.plant.substeps, st.wheel_res, st.steer_res,
                  st.u_ff, mode_d, alpha_d, alpha_dot_d, st.beta_d, beta_dot_d, st.noise.steering, st.noise.torque,
                  st.noise.torque_offset, t, burst, patches, st.pos, st.vel, st.cstate, st.work,
                  out["pos"], out["vel"], out["alpha"], out["beta"], out["cmd"], out["app"], out["meas"],
                  st.energy, out["work"])

    truths: list = []
    if settings.payload and vehicle is None:  # MuJoCo's: mujoco_stepper (mujoco_payload.py)
        from agvdyn.simulation.payload import payload_stepper

        step = payload_stepper(step, st.c, st.pos, st.vel, settings.payload, plant_params.m_ch, plant_params.C_ch,
                               Ts, truths)  # noqa: F811
    if vehicle is not None:
        from agvdyn.simulation.mujoco_plant import mujoco_stepper

        mj_energy = np.zeros((traj.n_samples, 2))
        step = mujoco_stepper(vehicle, traj, settings, st, burst, patches, mj_energy, truths)  # noqa: F811
    run_chunks(traj.name, traj.n_samples, Ts, st, step, progress)
    energy = st.energy
    if vehicle is not None:  # kinetic energy; dissipated work = motor work - change of kinetic + potential energy
        energy = mj_energy[:, 0]
        total = mj_energy.sum(axis=1)
        out["work"][:, 1] = out["work"][:, 0] - (total - total[0])
    return SimulationResult(
        traj, platform, plant_params, ctrl_params, settings, seed,
        out["pos"], out["vel"], st.q_dot_d, st.beta_d, st.u_ff, out["alpha"], out["beta"],
        out["cmd"], out["app"], out["meas"], energy, out["work"], burst, engine=engine, vehicle=vehicle,
        payload_truth=tuple(truths),
    )


#: Plants of :func:`simulate`.
ENGINES = ("ours", "mujoco")


def _mujoco_vehicle(platform: Geometry, plant_params: Parameters, settings: SimulationSettings, mjcf: Any,
                    split: Any, engine_options: Any) -> tuple[Any, Geometry, Parameters, SimulationSettings]:
    """The MuJoCo vehicle of a run, and the platform, true parameters and settings it implies (the
    wheel radius errors of the settings are the MuJoCo wheels')."""
    from dataclasses import replace

    from agvdyn.simulation.mujoco_model import BodySplit, EngineOptions
    from agvdyn.simulation.mujoco_plant import MujocoVehicle

    if mjcf is not None:
        if split is not None or engine_options is not None:
            raise ValueError(f"{mjcf}: an MJCF file fixes bodies and engine options: give no split or engine_options")
        if plant_params is not PAPER_PARAMETERS:
            raise ValueError(f"{mjcf}: the MJCF file holds the true parameters: give no plant_params")
        vehicle = MujocoVehicle.read(mjcf)
        if platform is not PROTOTYPE and not platform.same_shape(vehicle.geometry):
            raise ValueError(f"{mjcf}: its platform ({vehicle.geometry.describe()}) differs from the one given "
                             f"({platform.describe()})")
        errors = tuple(float(x) for x in vehicle.wheel_radii / vehicle.geometry.r - 1.0)
    else:
        errors = settings.plant.wheel_radius_error
        options = engine_options or EngineOptions()
        if options.wheel_radii is None:
            options = replace(options, wheel_radii=tuple(platform.r * (1.0 + e) for e in errors))
        vehicle = MujocoVehicle.generate(platform, plant_params, split=split or BodySplit(), options=options)
    settings = replace(settings, plant=replace(settings.plant, wheel_radius_error=errors))
    return vehicle, vehicle.geometry, vehicle.parameters, settings


def feedforward_table(experiment: str | os.PathLike | Trajectory, params: Parameters = PAPER_PARAMETERS,
                      platform: Geometry = PROTOTYPE, *, sample_time: float = SAMPLE_TIME,
                      limits: Limits | None = Limits(), engine: str = "python") -> pd.DataFrame:
    """Planned trajectory with its feed-forward motor torques of eq. (21), one row per sample.

    Columns: t, segment, mode (label), alpha_l, alpha_r, the planned q_dot (v_x, v_y, omega,
    alpha_l_dot, alpha_r_dot, beta_*_dot), planned wheel angles beta_*, and m_fl..m_rr (N m, motor side).
    A trajectory that breaks ``limits`` raises LimitError (``limits=None``: no check).
    ``engine``: ``"python"`` (the reference, :func:`agvdyn.dynamics.feedforward_torques`) or ``"cpp"``
    (the C++ library through :mod:`agvdyn.ffcpp`; CppEngineUnavailable when it was not built).
    """
    from agvdyn.ffcpp import check_engine, trajectory_feedforward

    check_engine(engine)
    traj = _trajectory(experiment, platform, sample_time)
    motion = traj.joint_motion()
    q_dot = motion[0]
    u = traj.feedforward(params) if engine == "python" else trajectory_feedforward(traj, params)
    if limits is not None:
        check_limits(traj, params, limits, motion=motion, torques=u)
    beta = traj.wheel_angles(q_dot)
    from agvdyn.kinematics import Mode

    labels = np.array([Mode(int(m)).label for m in traj.mode])
    data: dict[str, Any] = {"t": traj.t, "segment": traj.segment.astype(str), "mode": labels,
                            "alpha_l": traj.alpha[:, 0], "alpha_r": traj.alpha[:, 1]}
    vnames = ("v_x", "v_y", "omega", "alpha_l_dot", "alpha_r_dot", *(f"beta_{w}_dot" for w in WHEELS))
    data.update({n: q_dot[:, i] for i, n in enumerate(vnames)})
    data.update({f"beta_{w}": beta[:, i] for i, w in enumerate(WHEELS)})
    data.update({f"m_{w}": u[:, i] for i, w in enumerate(WHEELS)})
    return pd.DataFrame(data)


__all__ += ["TrajectoryError", "ENGINES"]
