"""The outcome of a closed-loop run (:func:`agvdyn.simulation.simulate`): true states, plan, sensor
signals, drive torques, energy and true slip, and the log and sidecar written from them."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from agvdyn._lazy import pandas as pd  # tables only (feedforward_table, the frames): simulating and writing a log need no pandas

from agvdyn.model_spec import FRICTION_GROUPS, ModelParameters, ModelSpec
from agvdyn.odometry import odometry
from agvdyn.platform import WHEELS, Geometry, Parameters
from agvdyn.simulation._kernels import contact_points, slip_speeds
from agvdyn.simulation.plant import PlantSettings, plant_constants
from agvdyn.simulation.settings import SimulationSettings
from agvdyn.simulation.slip import MERGE_GAP, SLIP_THRESHOLD, SlipInterval, slip_intervals as _slip_intervals
from agvdyn.trajectories import Trajectory, floor_space, pose_from_velocities

__all__ = ["SimulationResult"]


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
    Payload: ``payload_truth`` the loads picked up and dropped (:mod:`agvdyn.simulation.payload`).
    Model truth beyond the paper (issue 30): :attr:`true_model`.
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
    #: the payload events that happened (:class:`agvdyn.simulation.payload.PayloadTruth`), in time order
    payload_truth: tuple = ()

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

    def log_columns(self) -> dict[str, np.ndarray]:
        """The log in the PLATFORM.md schema as numpy columns: t, alpha_*, beta_* (wheel side), m_*
        (measured motor torques), segment (labels); what :meth:`write` writes (no pandas)."""
        data: dict[str, Any] = {"t": self.t, "alpha_l": self.alpha_measured[:, 0], "alpha_r": self.alpha_measured[:, 1]}
        for i, w in enumerate(WHEELS):
            data[f"beta_{w}"] = self.beta_measured[:, i]
        for i, w in enumerate(WHEELS):
            data[f"m_{w}"] = self.torque_measured[:, i]
        data["segment"] = self.segment.astype(str)
        return data

    def log_frame(self) -> pd.DataFrame:
        """:meth:`log_columns` as a DataFrame (the segment categorical)."""
        data = self.log_columns()
        data["segment"] = pd.Categorical(data["segment"])
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
        """:meth:`tracking_rows` as a table."""
        return pd.DataFrame(self.tracking_rows())

    def tracking_rows(self) -> list[dict[str, Any]]:
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
        return rows

    @property
    def whole_run_payload(self) -> Any:
        """The :class:`~agvdyn.simulation.payload.PayloadTruth` of a payload carried through the whole run
        (every event at sample 0), else None (no payload, or one that changes during the run)."""
        truths = self.payload_truth
        return truths[-1] if truths and all(p.sample == 0 for p in truths) else None

    @cached_property
    def true_model(self) -> ModelParameters:
        """The true model of the log (:class:`agvdyn.model_spec.ModelParameters`): the 11 parameters of
        the vehicle the log shows and the effects beyond the paper that are on.

        * breakaway friction (some group's ratio != 1; our plant with stiction, or MuJoCo's driving
          plant, mujoco_friction.py): ``friction="stribeck"``,
          ``d_sl, d_sr, d_sw`` = ratio * d_c of the group, ``w_sl, w_sr, w_sw`` its Stribeck velocity;
        * a torque delay (``SensorSettings.torque_delay``): ``delay_s``;
        * a payload carried through the whole run (:attr:`whole_run_payload`): ``m_ch``, ``C_ch`` (about
          the reference point) of the loaded chassis and its centre of mass ``x_c, y_c``
          (``com_offset`` when off the reference point). With payload changes during the run the
          parameters are those without a payload (``plant_params``; the loads' truth: ``payload_truth``).
        """
        params, extra = self.plant_params, {}
        groups = self.settings.plant.group_breakaway()
        has_breakaway = (self.settings.plant.coulomb == "stiction" if self.engine == "ours"
                         else not self.lifted)  # MuJoCo: mujoco_friction.py (not on jacks, mujoco_lifted.py)
        stribeck = has_breakaway and any(ratio != 1.0 for ratio, _ in groups)
        if stribeck:
            for (ratio, _), (name, (_, d_c)) in zip(groups, FRICTION_GROUPS.items()):
                extra[f"d_s{name}"] = ratio * getattr(params, d_c)
            extra.update((f"w_s{name}", w_s) for (_, w_s), name in zip(groups, FRICTION_GROUPS))
        load = self.whole_run_payload
        if load is not None:
            params = params.replace(m_ch=load.m_ch, C_ch=load.C_ch)
            extra.update(x_c=load.x_c, y_c=load.y_c)
        delay = self.settings.sensors.torque_delay
        spec = ModelSpec(friction="stribeck" if stribeck else "paper", delay=delay,
                         com_offset=load is not None and (load.x_c != 0.0 or load.y_c != 0.0),
                         stribeck_velocities=tuple(w for _, w in groups) if stribeck else None)
        return ModelParameters(params, extra, delay, spec)

    def _truth_entries(self) -> dict[str, Any]:
        """``true_parameters`` (the 11 of eq. 18, then the extra ones of :attr:`true_model`) and, when
        an effect beyond the paper or a whole-run payload is on, ``true_model`` {friction, delay_s,
        com_offset, stribeck_velocities}; without them exactly the paper's parameters."""
        truth = self.true_model
        out: dict[str, Any] = {"true_parameters": {**truth.parameters.to_dict(), **truth.extra}}
        if truth.spec.is_paper and self.whole_run_payload is None:
            return out
        model = {"friction": truth.spec.friction, "delay_s": truth.delay_s, "com_offset": truth.spec.com_offset}
        if truth.spec.stribeck_velocities is not None:
            model["stribeck_velocities"] = list(truth.spec.stribeck_velocities)
        return {**out, "true_model": model}

    def sidecar(self) -> dict[str, Any]:
        """YAML sidecar of the log: platform, true parameters (eq. 18 order, then those of the effects
        beyond the paper, :attr:`true_model`), seed, settings, summary, and the true slip intervals
        ``slip_truth`` (above ``slip_truth_threshold`` m/s)."""
        fs = floor_space(self.trajectory)
        truth = self._truth_entries()
        side = {
            "source": "agvdyn.simulation",
            "engine": self.engine,
            "experiment": self.experiment,
            "platform": self.geometry.to_dict(),
            "true_parameters": truth["true_parameters"],
            "controller_parameters": self.controller_params.to_dict(),
            "seed": int(self.seed),
            # the torque of row k is held over [t_k, t_k + T_s) (zero-order hold): seen from the
            # angle samples it leads by half a sample (IdentificationSettings.torque_lead)
            "torque_lead": 0.5,
            **({"true_model": truth["true_model"]} if "true_model" in truth else {}),
            "settings": self.settings.to_dict(),
            "plant": _plant_facts(self.geometry, self.plant_params, self.settings.plant),
            "floor_space": {"length": fs.length, "width": fs.width},
            "tracking": self.tracking_rows(),
            "slip_truth_threshold": SLIP_THRESHOLD,
            "slip_truth_merge_gap": MERGE_GAP,
            "slip_truth": [s.to_dict() for s in self.slip_intervals(SLIP_THRESHOLD)],
        }
        if self.payload_truth:  # truth of the payload changes (only when there are some: logs without unchanged)
            side["payload_truth"] = [p.to_dict() for p in self.payload_truth]
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
        return write_log(path, self.log_columns(), side)


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
