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

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from agvdyn.odometry import odometry
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME, WHEELS, Geometry, Parameters
from agvdyn.simulation._kernels import contact_points, run_chunk, slip_speeds
from agvdyn.simulation.controller import STATE_SIZE, ControllerSettings
from agvdyn.simulation._setup import desired_motion, prepare_run, run_chunks
from agvdyn.simulation.plant import PlantSettings, plant_constants, run_open_loop
from agvdyn.simulation.sensors import SensorSettings
from agvdyn.simulation.settings import SimulationSettings, read_settings, settings_from_dict
from agvdyn.simulation.slip import (
    MERGE_GAP,
    SLIP_SCENARIO,
    SLIP_THRESHOLD,
    FrictionPatch,
    SlipInterval,
    SlipSettings,
    TorqueBurst,
    slip_intervals as _slip_intervals,
)
from agvdyn.trajectories import (
    Limits,
    Trajectory,
    TrajectoryError,
    check_limits,
    experiment as build_experiment,
    floor_space,
    pose_from_velocities,
)

__all__ = [
    "ControllerSettings", "PlantSettings", "SensorSettings", "SimulationSettings", "SimulationResult",
    "simulate", "feedforward_table", "run_open_loop", "plant_constants", "read_settings", "settings_from_dict",
    "SlipSettings", "FrictionPatch", "TorqueBurst", "SlipInterval", "SLIP_SCENARIO", "SLIP_THRESHOLD",
]



@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Outcome of :func:`simulate`; arrays have the sample axis first (N rows at ``t``).

    True plant: ``position`` (N, 9) = (X, Y, gamma, alpha_l, alpha_r, beta_fl, beta_rl, beta_fr, beta_rr),
    ``velocity`` (N, 9) (body-frame chassis velocities, PLATFORM.md order). Plan: ``q_dot_d``,
    ``pose_d`` (N, 3), ``beta_d`` (N, 4), ``feedforward`` (N, 4). Sensors: ``alpha_measured`` (N, 2),
    ``beta_measured`` (N, 4), ``torque_measured`` (N, 4). Drive: ``torque_command`` (N, 4),
    ``torque_burst`` (N, 4) the slip scenario's torque bursts (zero without one) and
    ``torque_applied`` (N, 4) = command after the torque limit + burst, what the motors apply.
    Energy: ``energy`` (N,) kinetic energy, ``work`` (N, 3) cumulative (motor, dissipated, stops) work.
    True slip: ``slip_speed`` (N, 4), ``contact_points`` (N, 4, 2), :meth:`slip_intervals`.
    """

    trajectory: Trajectory
    geometry: Geometry
    plant_params: Parameters
    controller_params: Parameters
    settings: SimulationSettings
    seed: int
    position: np.ndarray
    velocity: np.ndarray
    q_dot_d: np.ndarray
    beta_d: np.ndarray
    feedforward: np.ndarray
    alpha_measured: np.ndarray
    beta_measured: np.ndarray
    torque_command: np.ndarray
    torque_applied: np.ndarray
    torque_measured: np.ndarray
    energy: np.ndarray
    work: np.ndarray
    torque_burst: np.ndarray
    lifted: bool = False
    #: ``"ours"`` or ``"mujoco"`` (ENGINES); ``vehicle`` the MuJoCo vehicle (mujoco_plant.MujocoVehicle) that ran
    engine: str = "ours"
    vehicle: Any = None

    @property
    def t(self) -> np.ndarray:
        return self.trajectory.t

    @property
    def segment(self) -> np.ndarray:
        return self.trajectory.segment

    @property
    def experiment(self) -> str:
        return self.trajectory.name

    @cached_property
    def pose_d(self) -> np.ndarray:
        """Planned pose (N, 3) in the world frame of the start."""
        return pose_from_velocities(self.q_dot_d[:, :3], self.settings.sample_time)

    @cached_property
    def _constants(self) -> np.ndarray:
        return plant_constants(self.geometry, self.plant_params, self.settings.plant)

    @cached_property
    def slip_speed(self) -> np.ndarray:
        """True slip speed (N, 4), m/s, of each wheel's contact point: the norm of its lateral and
        longitudinal slip velocity (rows of ``A(alpha) v``, eq. 1-2, with the true rolling radii)."""
        if self.lifted:  # no ground contact: nothing slips
            return np.zeros((self.t.size, 4))
        return slip_speeds(self._constants, self.position, self.velocity)

    @cached_property
    def contact_points(self) -> np.ndarray:
        """True world positions (N, 4, 2) of the contact points (frame of the start), m."""
        return contact_points(self._constants, self.position)

    def slip_intervals(self, threshold: float = SLIP_THRESHOLD, merge_gap: float = MERGE_GAP) -> list[SlipInterval]:
        """True slip intervals: runs of samples in which some wheel's :attr:`slip_speed` exceeds
        ``threshold`` (m/s), as ``SlipInterval(t_start, t_end, peak, wheels)`` (first and last sample
        time, peak slip speed in m/s, wheel names); runs at most ``merge_gap`` s apart are merged."""
        return _slip_intervals(self.t, self.slip_speed, threshold, merge_gap)

    @cached_property
    def odometry_pose(self) -> np.ndarray:
        """Pose (N, 3) by odometry, eq. (3), from the measured angles (central differences), as the vehicle sees it."""
        Ts = self.settings.sample_time
        if self.lifted:  # on jacks: the chassis does not move, whatever the wheels do
            return np.zeros((self.t.size, 3))
        a_dot = np.gradient(self.alpha_measured, Ts, axis=0)
        b_dot = np.gradient(self.beta_measured, Ts, axis=0)
        twist = odometry(self.geometry, self.alpha_measured, a_dot, b_dot)
        return pose_from_velocities(twist, Ts)

    def log_frame(self) -> pd.DataFrame:
        """The log in the PLATFORM.md schema: t, alpha_*, beta_* (wheel side), m_* (measured motor torques), segment."""
        data: dict[str, Any] = {"t": self.t, "alpha_l": self.alpha_measured[:, 0], "alpha_r": self.alpha_measured[:, 1]}
        for i, w in enumerate(WHEELS):
            data[f"beta_{w}"] = self.beta_measured[:, i]
        for i, w in enumerate(WHEELS):
            data[f"m_{w}"] = self.torque_measured[:, i]
        data["segment"] = pd.Categorical(self.segment.astype(str))
        return pd.DataFrame(data)

    def truth_frame(self) -> pd.DataFrame:
        """True plant states, plan and drive signals per sample (for plots and checks)."""
        names = ("X", "Y", "gamma", "alpha_l", "alpha_r", *(f"beta_{w}" for w in WHEELS))
        vnames = ("v_x", "v_y", "omega", "alpha_l_dot", "alpha_r_dot", *(f"beta_{w}_dot" for w in WHEELS))
        data: dict[str, Any] = {"t": self.t, "segment": self.segment.astype(str)}
        data.update({f"true_{n}": self.position[:, i] for i, n in enumerate(names)})
        data.update({f"true_{n}": self.velocity[:, i] for i, n in enumerate(vnames)})
        data.update({f"plan_{n}": self.q_dot_d[:, i] for i, n in enumerate(vnames)})
        data.update({f"plan_{n}": self.pose_d[:, i] for i, n in enumerate(("X", "Y", "gamma"))})
        data.update({f"plan_alpha_{s}": self.trajectory.alpha[:, i] for i, s in enumerate("lr")})
        data.update({f"odometry_{n}": self.odometry_pose[:, i] for i, n in enumerate(("X", "Y", "gamma"))})
        for key in ("feedforward", "torque_command", "torque_applied", "torque_burst", "slip_speed"):
            data.update({f"{key}_{w}": getattr(self, key)[:, i] for i, w in enumerate(WHEELS)})
        return pd.DataFrame(data)

    def tracking(self) -> pd.DataFrame:
        """Tracking errors and odometry drift per segment (one row per segment, in time order).

        steering_max: max |alpha - alpha_d| (rad); wheel_speed_rms: RMS of beta_dot - beta_dot_d
        (rad/s); speed_rms: RMS of |(v_x, v_y) - planned| (m/s); yaw_rate_rms (rad/s); at the segment
        end: position_error / heading_error of the true pose against the plan (m, rad, accumulated
        from the start of the run) and odometry_drift / odometry_heading_drift of the odometry
        pose against the true pose; saturated: share of samples with a torque at the limit.
        """
        rows = []
        pose = self.position[:, :3]
        lim = math.inf if self.settings.plant.torque_limit is None else self.settings.plant.torque_limit
        saturated = np.any(np.abs(self.torque_command) > lim, axis=1)
        for name, sl in self.trajectory.segment_slices():
            end = sl.stop - 1
            dv = self.velocity[sl] - self.q_dot_d[sl]
            rows.append({
                "segment": name,
                "t_start": float(self.t[sl.start]),
                "t_end": float(self.t[end]),
                "steering_max": float(np.abs(self.position[sl, 3:5] - self.trajectory.alpha[sl]).max()),
                "wheel_speed_rms": float(np.sqrt(np.mean(dv[:, 5:] ** 2))),
                "speed_rms": float(np.sqrt(np.mean(dv[:, 0] ** 2 + dv[:, 1] ** 2))),
                "yaw_rate_rms": float(np.sqrt(np.mean(dv[:, 2] ** 2))),
                "position_error": float(np.hypot(*(pose[end, :2] - self.pose_d[end, :2]))),
                "heading_error": float(abs(pose[end, 2] - self.pose_d[end, 2])),
                "odometry_drift": float(np.hypot(*(self.odometry_pose[end, :2] - pose[end, :2]))),
                "odometry_heading_drift": float(abs(self.odometry_pose[end, 2] - pose[end, 2])),
                "saturated": float(np.mean(saturated[sl])),
            })
        return pd.DataFrame(rows)

    def sidecar(self) -> dict[str, Any]:
        """YAML sidecar of the log: platform, true parameters (eq. 18 order), seed, settings, summary,
        and the true slip intervals ``slip_truth`` (above ``slip_truth_threshold`` m/s)."""
        fs = floor_space(self.trajectory)
        side = {
            "source": "agvdyn.simulation",
            "engine": self.engine,
            "experiment": self.experiment,
            "platform": self.geometry.to_dict(),
            "true_parameters": self.plant_params.to_dict(),
            "controller_parameters": self.controller_params.to_dict(),
            "seed": int(self.seed),
            # the torque of row k is held over [t_k, t_k + T_s) (zero-order hold): seen from the
            # angle samples it leads by half a sample (IdentificationSettings.torque_lead)
            "torque_lead": 0.5,
            "settings": self.settings.to_dict(),
            "plant": _plant_facts(self.geometry, self.plant_params, self.settings.plant),
            "floor_space": {"length": fs.length, "width": fs.width},
            "tracking": self.tracking().to_dict(orient="records"),
            "slip_truth_threshold": SLIP_THRESHOLD,
            "slip_truth_merge_gap": MERGE_GAP,
            "slip_truth": [s.to_dict() for s in self.slip_intervals(SLIP_THRESHOLD)],
        }
        if self.vehicle is not None:  # MuJoCo: the engine's facts replace our plant's
            side["plant"] = {"wheel_radii": [float(x) for x in self.vehicle.wheel_radii],
                             "torque_limit": self.settings.plant.torque_limit}
            side["mujoco"] = self.vehicle.facts()
        return side

    def write(self, path: str | os.PathLike) -> Path:
        """Write the log (Parquet by default, CSV by suffix) and its YAML sidecar atomically; on MuJoCo
        also the MJCF that ran, beside the log as ``<path>.mjcf.xml`` (sidecar: ``mujoco.mjcf``)."""
        from agvdyn._files import write_text_atomically
        from agvdyn.io import write_log

        side = self.sidecar()
        if self.vehicle is not None:
            from agvdyn.simulation.mujoco_plant import MJCF_SUFFIX

            model_path = Path(str(path) + MJCF_SUFFIX)
            write_text_atomically(model_path, self.vehicle.xml)
            side["mujoco"]["mjcf"] = model_path.name
        return write_log(path, self.log_frame(), side)


def _plant_facts(geom: Geometry, params: Parameters, plant: PlantSettings) -> dict[str, Any]:
    """Derived quantities of the simulated vehicle (for the sidecar)."""
    from agvdyn.simulation import plant as _plant

    c = plant_constants(geom, params, plant)
    return {
        "unit_mass": float(c[_plant._MU_MASS]), "unit_offset": float(c[_plant._EU]),
        "chassis_body_mass": float(c[_plant._MB]), "chassis_body_inertia": float(c[_plant._CB]),
        "wheel_radii": [float(x) for x in c[_plant._RW:_plant._RW + 4]],
        "wheel_load": float(c[_plant._FZ]),
    }


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
    if traj.lifted and vehicle is not None:
        raise ValueError(f"experiment {traj.name!r}: the lifted-wheel experiment runs on engine='ours' only")
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

    if vehicle is not None:
        from agvdyn.simulation.mujoco_plant import mujoco_stepper

        mj_energy = np.zeros((traj.n_samples, 2))
        step = mujoco_stepper(vehicle, traj, settings, st, burst, patches, mj_energy)  # noqa: F811
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
