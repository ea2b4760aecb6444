"""Predicted statistics of a sequence: rows kept, information matrix, cond, default sequence for a floor."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from agvdyn.determinacy import std_from_information
from agvdyn.dynamics import projected_regressor
from agvdyn.kinematics import Mode, joint_motion, kinematic_model
from agvdyn.model_spec import ModelParameters, ModelSpec
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME, Geometry, Parameters
from agvdyn.row_rules import row_mask
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import default_excitation, default_periods, identification_sequence
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.limits import FloorSpace, Limits, floor_space, limit_report
from agvdyn.trajectories.segments import Trajectory
from agvdyn.trajectories.planner.problem import _sequence
from agvdyn.trajectories.planner.model_columns import extra_names, segment_columns, stribeck_velocities
from agvdyn.trajectories.planner.weights import _row_weights
from agvdyn.trajectories.planner.settings import _OFFSETS, FREE, PlanSettings

if TYPE_CHECKING:
    pass


@dataclass(frozen=True)
class SequenceEvaluation:
    """Predicted quality of an identification sequence (exact rows at T_s, the identification's mask).

    ``cond``: cond(Theta_1w^T Theta_1w) of the column-scaled regressor of the ten parameters (eq. 25);
    ``std``: predicted standard deviations (from the information matrix with the noise levels,
    motor-torque offsets estimated alongside); ``floor``: the rectangle it occupies (sec. 6.2);
    ``duration`` s; ``peak_torque`` the largest feed-forward motor torque (N m).
    """

    cond: float
    std: dict[str, float]
    relative_std: dict[str, float]
    floor: FloorSpace
    duration: float
    peak_torque: float
    correlation: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"cond": self.cond, "std": dict(self.std), "relative_std": dict(self.relative_std),
                "floor": {"length": self.floor.length, "width": self.floor.width}, "duration": self.duration,
                "peak_torque": self.peak_torque, "correlation": dict(self.correlation)}


def _coordinates(seg) -> list[tuple[int, str]]:
    if seg.name == "steer_left":
        return [(0, "alpha_l")]
    if seg.name == "steer_right":
        return [(1, "alpha_r")]
    return list(enumerate(seg.mode.coordinates))


def _sequence_rows(traj: Trajectory, settings: PlanSettings, *, validity: bool = False, with_bw: bool = False,
                   model: ModelParameters | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows (m, 10 + 4) of eq. (19) the identification keeps (ten parameters, with ``with_bw`` eleven,
    then the columns of ``model``'s extensions (:mod:`.model_columns`), then the offset columns), the
    noise level of each row's coordinate and the row's variance factor
    (:meth:`NoiseLevels.variance_factor`); ``validity``: the optimiser's smooth weights instead of
    the mask, and its noise levels (``PlanSettings.levels``)."""
    g = traj.geometry
    n_p = 11 if with_bw else 10
    spec = None if model is None or model.spec.is_paper else model.spec
    n_x = 0 if spec is None else len(extra_names(spec))
    noise = settings.levels(weights=validity)
    rows, sig, fac = [], [], []
    for seg in traj.segments:
        if seg.lifted:  # no rows of the vehicle
            continue
        qd, qdd = joint_motion(g, seg.mode, seg.alpha, seg.s_dot, seg.s_ddot)
        Y = projected_regressor(g, seg.mode, seg.alpha, qd, qdd)
        H = kinematic_model(g, seg.mode, seg.alpha)
        X = None
        if spec is not None:
            u = seg.feedforward(g, model.parameters, (qd, qdd)) if spec.delay != 0.0 else np.zeros((len(qd), 4))
            X = segment_columns(g, spec, stribeck_velocities(model), H, qd, qdd, u, traj.sample_time, Y)
        for j, coord in ([(0, "alpha_l"), (1, "alpha_r")] if seg.mode is Mode.PARKING else _coordinates(seg)):
            v = seg.s_dot[:, j]
            th = settings.threshold(coord)
            if validity:
                keep_w = _row_weights(v, seg.s_ddot[:, j], th, noise.knee(coord), settings,
                                      noise.saturation, settings.guard(coord, weights=True)).wU
                keep = keep_w > 1e-6
            else:
                keep = row_mask(v, th, settings.guard_samples(coord, traj.sample_time))  # the identification's
                keep_w = keep.astype(float)
            if not keep.any():
                continue
            offs = g.i_G * H[keep, 5:, j] if settings.torque_offsets else np.zeros((int(keep.sum()), _OFFSETS))
            extra = X[keep, j, :] if X is not None else np.zeros((int(keep.sum()), 0))
            block = np.concatenate([Y[keep, j, :n_p], extra, offs], axis=1) * np.sqrt(keep_w[keep])[:, None]
            rows.append(block)
            sig.append(np.full(int(keep.sum()), noise.of(coord)))
            fac.append(noise.variance_factor(coord, seg.s_ddot[keep, j]))
    if not rows:
        return np.zeros((0, n_p + n_x + _OFFSETS)), np.zeros(0), np.zeros(0)
    return np.concatenate(rows), np.concatenate(sig), np.concatenate(fac)


def _information(A: np.ndarray, sig: np.ndarray, n_p: int = 10) -> tuple[np.ndarray, np.ndarray]:
    Aw = A / sig[:, None]
    return Aw.T @ Aw, A[:, :n_p].T @ A[:, :n_p]


def _row_variance(A: np.ndarray, sig: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """Omega of the sandwich: the rows' information times their variance factor."""
    Aw = A / sig[:, None]
    return (Aw * factor[:, None]).T @ Aw


def evaluate_sequence(traj: Trajectory, params: Parameters = PAPER_PARAMETERS, limits: Limits = Limits(),
                      settings: PlanSettings = PlanSettings(), *, estimate_bw: bool = False,
                      model: ModelSpec | ModelParameters | None = None) -> SequenceEvaluation:
    """Predicted cond, standard deviations, floor, duration and peak torque of an identification
    sequence, from its planned motion with the identification's stiction mask and guard.

    The stds are those of the weighted least squares with one weight per coordinate (the
    identification's ``wls``) under rows whose effective variance grows with the acceleration
    (:class:`NoiseLevels`): the sandwich ``F^-1 Omega F^-1``, ``Omega`` the rows' information
    times their variance factor.

    ``estimate_bw``: B_w estimated with the others (``identify --fix none``) instead of known; its
    std is then in ``std`` too (infinite when the motion does not determine it).

    ``model``: the model beyond the paper that will be identified (issue 30; a ModelSpec, or a
    ModelParameters whose values set the Stribeck velocities, the offset and the planned torques):
    its estimated parameters are in ``std`` too (:mod:`.model_columns`): ``d_sl, d_sr, d_sw``,
    ``y_c`` (and ``x_c``, infinite: no mode of this vehicle excites it), ``delay_s``.
    """
    names = FREE + (("B_w",) if estimate_bw else ())
    n_p = len(names)
    model = _model_values(model, params)
    A, sig, factor = _sequence_rows(traj, settings, with_bw=estimate_bw, model=model)
    F, U = _information(A, sig, n_p)
    Omega = _row_variance(A, sig, factor)
    d, cov, det, _ = std_from_information(F, Omega)
    std = d[:n_p]
    extra = _extra_std(model, d, cov, n_p, names)
    corr: dict[str, float] = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        r = cov / np.outer(d, d)
    for p_, q_ in (("d_vl", "d_cl"), ("d_vr", "d_cr"), ("d_vw", "d_cw"), ("C_r", "C_ch"), ("C_l", "C_ch")):
        i, j = FREE.index(p_), FREE.index(q_)
        if not (det.undetermined[i] or det.undetermined[j]):
            corr[f"{p_}/{q_}"] = float(r[i, j])
    cond = _cond(U)
    p = params.to_vector()[:n_p]
    report = limit_report(traj, params, limits)
    return SequenceEvaluation(
        cond=cond, std={**{n: float(s) for n, s in zip(names, std)}, **extra},
        relative_std={n: float(s / abs(v)) for n, s, v in zip(names, std, p)},
        floor=floor_space(traj), duration=traj.duration, peak_torque=report.peaks["motor_torque"],
        correlation=corr)


def _model_values(model: ModelSpec | ModelParameters | None, params: Parameters) -> ModelParameters | None:
    """The model as values: a spec gets ``params`` and the paper's law for its extras (``d_s = d_c``,
    the offset 0, its Stribeck velocities or the middle of its range)."""
    if model is None or isinstance(model, ModelParameters):
        return model
    spec = model.replace(delay=0.0 if model.delay == 0.0 else model.delay)
    extra = {}
    if spec.stribeck:
        w_s = stribeck_velocities(spec)
        extra.update({f"d_s{g}": getattr(params, f"d_c{g}") for g in "lrw"})
        extra.update({f"w_s{g}": w for g, w in zip("lrw", w_s)})
    if spec.com_offset:
        extra.update(x_c=0.0, y_c=0.0)
    return ModelParameters(params, extra, 0.0 if spec.delay == "auto" else float(spec.delay), spec)


def _extra_std(model: ModelParameters | None, d: np.ndarray, cov: np.ndarray, n_p: int,
               names: tuple[str, ...]) -> dict[str, float]:
    """Predicted stds of the extensions' parameters; ``y_c = (m_ch y_c) / m_ch`` by the delta method."""
    if model is None or model.spec.is_paper:
        return {}
    out = {}
    for k, name in enumerate(extra_names(model.spec)):
        i = n_p + k
        if name != "y_c":
            out[name] = float(d[i])
            continue
        m, y_c, j = model.parameters.m_ch, model.value("y_c"), names.index("m_ch")
        if not (math.isfinite(d[i]) and math.isfinite(d[j])):
            out["y_c"] = math.inf
            continue
        grad = np.array([1.0 / m, -y_c / m])  # d y_c / d (m y_c, m_ch), m y_c's column holds m_ch y_c
        sub = cov[np.ix_([i, j], [i, j])]
        out["y_c"] = float(math.sqrt(max(grad @ sub @ grad, 0.0)))
    if model.spec.com_offset:
        out["x_c"] = math.inf  # its column vanishes in every mode (model_columns)
    out.update(dict.fromkeys(model.spec.held, math.inf))  # held at the paper's law: not estimated
    return out


def _cond(U: np.ndarray) -> float:
    diag = np.diag(U)
    if np.any(diag <= 0):
        return math.inf
    d = 1 / np.sqrt(diag)
    lam = np.linalg.eigvalsh(U * np.outer(d, d))
    return float(lam[-1] / lam[0]) if lam[0] > 0 else math.inf


# --- the default sequence in a given floor and duration --------------------------------------------

def default_for_floor(geom: Geometry = PROTOTYPE, floor: FloorSpace | None = None, duration: float | None = None,
                      limits: Limits = Limits(), *, settings: PlanSettings = PlanSettings(),
                      dt: float = SAMPLE_TIME) -> Trajectory:
    """The default identification sequence (``default_excitation``) fitted into a floor and a duration.

    The straight's excursion is scaled down to the floor length; with another total duration the
    periods of the four phases are stretched alike (peak rates kept, excursions scaled down where
    a limit requires it). Without floor and duration: the default sequence itself.
    """
    base = identification_sequence(geom, pause=settings.pause, dt=dt, align_rate=settings.align_rate,
                                   align_acceleration=settings.align_acceleration)
    if floor is None and duration is None:
        return replace(base, name="default")
    aligns = sum(s.duration + dt for s in base.segments if s.name == "align")
    phases = base.duration - aligns
    factor = 1.0 if duration is None else (duration - aligns) / phases
    if factor <= 0.05:
        raise TrajectoryError(f"duration {duration} s: shorter than the alignments of the sequence ({aligns:.1f} s)")
    half = math.inf if floor is None else (floor.length - geom.l) / 2
    if half <= 0:
        raise TrajectoryError(f"floor length {floor.length:g} m: shorter than the vehicle (l = {geom.l:g} m)")
    peaks = {"steer_left": (1.5, 0.9), "steer_right": (1.5, 0.9), "straight": (0.8, 2.0), "rotation": (0.7, 1.6)}
    series = {}
    for name, (v_peak, q_peak) in peaks.items():
        s = default_excitation(name)
        if name == "straight":
            q_peak = min(q_peak, half)
        series[name] = FourierSeries.at_rest(s.base_frequency / factor, s.a, s.b, peak_velocity=v_peak,
                                             peak_excursion=q_peak)
    traj = _sequence(geom, series, settings, dt, steering_periods=default_periods("steer_left"), name="default")
    report = limit_report(traj, PAPER_PARAMETERS, limits)
    if not report.ok:  # a shorter period can break an acceleration limit: scale every phase down to fit
        worst = min(report.limits[k] / report.peaks[k] for k in report.peaks)
        series = {k: FourierSeries(v.base_frequency, tuple(np.array(v.a) * worst * 0.99),
                                   tuple(np.array(v.b) * worst * 0.99)) for k, v in series.items()}
        traj = _sequence(geom, series, settings, dt, steering_periods=default_periods("steer_left"), name="default")
    return traj


# --- the plan --------------------------------------------------------------------------------------
