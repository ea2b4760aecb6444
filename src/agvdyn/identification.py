"""Identification of the dynamic parameters from logs: stacked regression of eq. (22)-(25).

Pipeline (paper sec. 6-7)::

    logs -> signals per run of one mode (filtered angles, derivatives, odometry eq. 3)
         -> rows H_k^T Theta p = H_k^T B u of eq. (19) per sample and generalized coordinate
         -> filtering of both sides ("parallel", default) or of the torques only ("literal")
         -> stiction rows dropped (|s_dot| below a threshold, sec. 7)
         -> stacked system Theta_hat p = tau_hat (eq. 22), known parameters to the right (eq. 24)
         -> rank check with the names of what is not excited
         -> column scaling W and least squares (eq. 25), standard deviations from the residual.

The entry point is :func:`identify`; :func:`equation_block` builds the rows of one run from
given (exact or measured) joint motion, :func:`log_equations` from a log.
"""
from __future__ import annotations

import math
import os
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import pandas as pd
import scipy.linalg

from agvdyn.dynamics import N_P, projected_input, projected_regressor
from agvdyn.identifiability import base_parameters_of, triangular_factor
from agvdyn.kinematics import MODE_TOLERANCE, Mode, detect_mode, kinematic_model, odometry
from agvdyn.platform import (
    EPSILON,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    PROTOTYPE,
    Geometry,
    ParameterFile,
    Parameters,
    read_platform,
    write_parameters,
)
from agvdyn.signals import (
    FilterSettings,
    filtered_derivatives,
    guarded_mask,
    lowpass,
    modes_from_segments,
    parallel_filter,
    runs,
    stiction_mask,
    time_derivative,
    uniform_sample_time,
)

__all__ = [
    "DEFAULT_FIXED",
    "EXCITATION",
    "Filtering",
    "IdentificationSettings",
    "EquationBlock",
    "UnidentifiableError",
    "Dependency",
    "Estimator",
    "LeastSquares",
    "Identification",
    "equation_block",
    "log_equations",
    "stacked_system",
    "dependent_parameters",
    "variance_inflation",
    "identify",
    "fit_blocks",
    "load_logs",
    "platform_for",
]

#: Parameters taken as known by default (eq. 24): B_w from a single-axis test (sec. 7).
DEFAULT_FIXED: Mapping[str, float] = MappingProxyType({"B_w": 0.121})

#: Names of the motor-torque offsets (nuisance parameters, motor side, N m).
OFFSET_NAMES = ("offset_fl", "offset_rl", "offset_fr", "offset_rr")

#: Which experiment excites each parameter (Table 1, PLATFORM.md segment names).
EXCITATION: Mapping[str, str] = MappingProxyType({
    "C_l": "steer_left (mode 1: steering the left wheel set at rest)",
    "d_vl": "steer_left (mode 1: steering the left wheel set at rest)",
    "d_cl": "steer_left (mode 1: steering the left wheel set at rest)",
    "C_r": "steer_right (mode 1: steering the right wheel set at rest)",
    "d_vr": "steer_right (mode 1: steering the right wheel set at rest)",
    "d_cr": "steer_right (mode 1: steering the right wheel set at rest)",
    "m_ch": "straight (mode 2 with alpha_v = 0) or lateral (mode 3)",
    "C_ch": "rotation (mode 4)",
    "d_vw": "straight, lateral or rotation",
    "d_cw": "straight, lateral or rotation",
    "B_w": "a car-like steered motion (mode 2, e.g. lane_change), or fix it from a single-axis test (--fix B_w=...)",
    **dict.fromkeys(OFFSET_NAMES, "the four identification segments together (steer_left, steer_right, straight and "
                                  "rotation each see another combination of the motor offsets), or no offset "
                                  "estimation (--no-offsets)"),
})

#: Order in which the rank check accepts columns: the representative the paper names for each
#: group of parameters that multiply the same signal comes first (Table 1: C_ch in rotation,
#: m_ch in straight motion), B_w last (the paper's dependent parameter p_2, sec. 6.3).
_RANK_ORDER = ("m_ch", "C_ch", "d_vw", "d_cw", "C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr", "B_w", *OFFSET_NAMES)


#: Generalized coordinates of the steering (eq. 10, 11) and of the chassis (eq. 11-13).
STEERING_COORDINATES = ("alpha_l", "alpha_r", "alpha_v")
CHASSIS_COORDINATES = ("x_ch", "y_ch", "gamma_ch")


class Filtering(str, Enum):
    """How measurement noise is filtered out of eq. (19).

    PARALLEL (default): the same zero-phase low-pass on every regressor column (tanh Coulomb
    columns included) and on the torques, so both sides of the equation see the same filter.
    LITERAL: the paper's wording: filtered angles and derivatives, filtered torques, tanh of
    the filtered velocity, no filtering of the regressor columns themselves.
    """

    PARALLEL = "parallel"
    LITERAL = "literal"


@dataclass(frozen=True)
class IdentificationSettings:
    """Settings of :func:`identify` (all tuning constants in one frozen place).

    Parameters
    ----------
    filter : FilterSettings
        Zero-phase low-pass (cut-off 40 rad/s by default, sec. 7).
    filtering : Filtering
        PARALLEL (default) or LITERAL, see :class:`Filtering`.
    stiction_threshold : float
        Rows of the chassis coordinates (x_ch, y_ch in m/s, gamma_ch in rad/s) whose generalized
        velocity ``|s_dot_k,i|`` is below this are dropped (sec. 7).
    steering_threshold : float
        The same for the steering coordinates (alpha_l, alpha_r, alpha_v), rad/s. Larger by
        default: the steering torque is dominated by Coulomb friction (13-17 N m against about
        1 N m of inertia torque), and the rows around a velocity reversal, where the acceleration
        that excites C_l, C_r is largest, are where stick/slip and wheel slip break the tanh model.
    mode_tolerance : float
        Tolerance (rad) of the mode relations (eq. 9) when the rows of a run are projected.
    epsilon : float
        Width of the tanh Coulomb model, rad/s.
    segments : tuple of str or None
        Segment names used; None: every segment with a mode (see ``signals.SEGMENT_MODES``).
    rank_tolerance : float
        A parameter is not identifiable when its (unit-norm) column has a component of relative
        size below this orthogonal to the columns accepted before it.
    sample_jitter : float
        Largest relative deviation of a time step from the median inside a run.
    stiction_guard : float
        Rows within ``stiction_guard / filter.cutoff`` seconds of a stiction row (or of the end
        of a run) are dropped too (2 / omega_g = 50 ms by default): the zero-phase filter
        spreads each sample over about that time, so their filtered values carry the low-speed
        effects the model does not describe. 0 switches it off.
    torque_offsets : bool
        Estimate a constant offset of each motor-torque measurement (motor side, N m) together
        with p, as four nuisance parameters shared by all logs of the identification (one
        recording session). Their columns are ``H_k^T B e_i``, so the offsets are exact in every
        mode. False: the paper's model without offsets. See docs/identification.md.
    rest_speed : float
        Logs without ``segment`` column: a row whose wheel surface speed not explained by
        steering is below this (m/s) is taken as mode 1 (at rest), see ``_detected_labels``.
    max_inflation : float
        A parameter whose variance inflation factor ``[(Theta_1,w^T Theta_1,w)^-1]_jj`` (unit-norm
        columns) exceeds this is refused as nearly a combination of others. Well-excited data
        give a few units (about 5 on the identification sequence); the lane change alone gives
        300 to 1,200 for the steering friction.
    max_relative_std : float
        A parameter whose standard deviation exceeds this fraction of its magnitude is refused
        as not excited enough (the paper's own worst is 0.28, d_vr in Table 2). ``inf`` switches
        both quality checks off.
    """

    filter: FilterSettings = FilterSettings()
    filtering: Filtering = Filtering.PARALLEL
    stiction_threshold: float = 0.05
    steering_threshold: float = 0.1
    torque_offsets: bool = True
    stiction_guard: float = 2.0
    mode_tolerance: float = MODE_TOLERANCE
    epsilon: float = EPSILON
    segments: tuple[str, ...] | None = None
    rank_tolerance: float = 1e-6
    sample_jitter: float = 0.05
    rest_speed: float = 0.01
    max_inflation: float = 100.0
    max_relative_std: float = 0.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "filtering", Filtering(self.filtering))
        for key in ("stiction_threshold", "steering_threshold", "stiction_guard", "mode_tolerance", "epsilon", "rank_tolerance", "sample_jitter",
                    "rest_speed"):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"identification setting {key}={value!r}: expected a finite number >= 0")
        for key in ("max_inflation", "max_relative_std"):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or math.isnan(value) or value <= 0:
                raise ValueError(f"identification setting {key}={value!r}: expected a number > 0 (inf: no check)")
        if self.epsilon <= 0 or self.mode_tolerance <= 0:
            raise ValueError("identification settings epsilon and mode_tolerance must be > 0")
        if self.segments is not None:
            object.__setattr__(self, "segments", tuple(str(s) for s in self.segments))

    def thresholds(self) -> dict[str, float]:
        """Stiction threshold of each generalized coordinate name."""
        steering = dict.fromkeys(STEERING_COORDINATES, self.steering_threshold)
        return {**dict.fromkeys(CHASSIS_COORDINATES, self.stiction_threshold), **steering}

    def to_dict(self) -> dict[str, Any]:
        return {
            "filter_cutoff_rad_s": self.filter.cutoff,
            "filter_order": self.filter.order,
            "derivative": self.filter.derivative.value,
            "filtering": self.filtering.value,
            "stiction_threshold": self.stiction_threshold,
            "steering_threshold": self.steering_threshold,
            "mode_tolerance": self.mode_tolerance,
            "epsilon": self.epsilon,
            "segments": None if self.segments is None else list(self.segments),
            "rank_tolerance": self.rank_tolerance,
            "torque_offsets": self.torque_offsets,
            "stiction_guard": self.stiction_guard,
            "rest_speed": self.rest_speed,
            "max_inflation": self.max_inflation,
            "max_relative_std": self.max_relative_std,
        }


@dataclass(frozen=True, eq=False)
class EquationBlock:
    """Rows of eq. (19) for one contiguous run in one motion mode.

    Attributes
    ----------
    source, segment : where the rows come from (file name, segment name or detected mode).
    mode : motion mode k of the run.
    t : (n,) time, s.
    regressor : (n, n_k, 11) ``H_k^T Theta`` as used in the regression (filtered when set so).
    torque : (n, n_k) ``H_k^T B u`` as used in the regression.
    s_dot : (n, n_k) generalized velocities (eq. 10-13).
    keep : (n, n_k) rows kept after the stiction mask.
    offset_regressor : (n, n_k, 4) ``H_k^T B e_i``: generalized torques of a unit offset of each
        motor-torque measurement (filtered like the regressor).
    """

    source: str
    segment: str
    mode: Mode
    t: np.ndarray
    regressor: np.ndarray
    torque: np.ndarray
    s_dot: np.ndarray
    keep: np.ndarray
    offset_regressor: np.ndarray

    @property
    def coordinates(self) -> tuple[str, ...]:
        return self.mode.coordinates

    def model_torque(self, p: np.ndarray, offsets: np.ndarray | None = None) -> np.ndarray:
        """Model generalized torques ``H_k^T Theta p`` (n, n_k), plus ``H_k^T B o`` of motor-torque
        offsets ``o`` (4,) when given (the model of the *measured* torques)."""
        out = self.regressor @ np.asarray(p, dtype=float)
        if offsets is not None:
            out = out + self.offset_regressor @ np.asarray(offsets, dtype=float)
        return out


def _generalized_velocity(H: np.ndarray, q_dot: np.ndarray) -> np.ndarray:
    """s_dot = H^+ q_dot (least squares on the kinematic model of eq. 4), (n, n_k)."""
    if H.strides[0] == 0:  # constant model broadcast over samples
        return q_dot @ np.linalg.pinv(H[0]).T
    normal = np.einsum("nik,nij->nkj", H, H)
    rhs = np.einsum("nik,ni->nk", H, q_dot)
    return np.linalg.solve(normal, rhs[..., None])[..., 0]


def equation_block(geometry: Geometry, mode: Mode | str, alpha: np.ndarray, q_dot: np.ndarray,
                   q_ddot: np.ndarray, u: np.ndarray, *, t: np.ndarray | None = None, segment: str = "",
                   source: str = "", stiction_threshold: float | Mapping[str, float] = 0.0, epsilon: float = EPSILON,
                   mode_tolerance: float = MODE_TOLERANCE) -> EquationBlock:
    """Rows ``H_k^T Theta(q, q_dot, q_ddot)`` and ``H_k^T B u`` of eq. (19) from given joint motion.

    No filtering: the signals are used as given (exact model signals, or already filtered
    measurements). Rows with ``|s_dot| < stiction_threshold`` are marked not kept; the threshold
    is one number or one per coordinate name (``mode.coordinates``).
    """
    mode = Mode.from_label(mode)
    alpha = np.asarray(alpha, dtype=float)
    n = alpha.shape[0]
    try:
        H = kinematic_model(geometry, mode, alpha, tolerance=mode_tolerance)
        Y = projected_regressor(geometry, mode, alpha, q_dot, q_ddot, epsilon=epsilon, tolerance=mode_tolerance)
        tau = projected_input(geometry, mode, alpha, u, tolerance=mode_tolerance)
    except ValueError as exc:
        where = f"{source}: " if source else ""
        raise ValueError(f"{where}segment {segment!r} (mode {mode.label}): {exc}") from exc
    s_dot = _generalized_velocity(H, np.asarray(q_dot, dtype=float))
    unit = np.eye(4)
    offset = np.stack([projected_input(geometry, mode, alpha, np.broadcast_to(unit[i], (n, 4)),
                                       tolerance=mode_tolerance) for i in range(4)], axis=2)
    if isinstance(stiction_threshold, Mapping):
        stiction_threshold = np.array([stiction_threshold[c] for c in mode.coordinates])
    keep = stiction_mask(s_dot, stiction_threshold)
    t = np.arange(n, dtype=float) if t is None else np.asarray(t, dtype=float)
    return EquationBlock(source, segment, mode, t, Y, tau, s_dot, keep, offset)


def _segment_runs(log: Any, settings: IdentificationSettings) -> list[tuple[int, int, str, str]] | None:
    """Runs ``(start, stop, segment name, mode label)`` of the ``segment`` column (label ``""``:
    not used); None when the log has no segment column."""
    source = str(getattr(log, "path", None) or "<log>")
    segments = getattr(log, "segments", None)
    if segments is None:
        return None
    segments = np.asarray(segments)
    bounds = runs(segments)
    names = [str(segments[a]) for a, _ in bounds]
    known = sorted({n for n in names if n})
    table = dict(zip(known, modes_from_segments(np.array(known, dtype=object), source=f"{source}: column 'segment'")))
    table[""] = ""
    out = []
    for (start, stop), name in zip(bounds, names):
        label = table[name]
        if settings.segments is not None and name not in settings.segments:
            label = ""
        out.append((start, stop, name, label))
    return out


def _detected_labels(geometry: Geometry, kin: "_Kinematics", settings: IdentificationSettings
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(name, mode label) per row detected from the filtered signals.

    Eq. (9) tells the mode from the steering angles alone, but a platform at rest is in mode 1
    whatever its angles (steering at rest, e.g. passing alpha = (0, 0) while steering one side).
    So a row whose wheel rates are explained by steering alone, i.e. the wheel surface speed left
    after subtracting the steering-induced rolling of H_1 is below ``settings.rest_speed``, is
    mode 1; the others get the mode of eq. (9) (``kinematics.detect_mode``).
    """
    detected = detect_mode(geometry, kin.alpha, settings.mode_tolerance).astype(int)
    H1 = kinematic_model(geometry, Mode.PARKING, kin.alpha[:1])[0]
    rolling = kin.beta_dot - kin.alpha_dot @ H1[5:].T
    at_rest = np.max(np.abs(rolling), axis=1) * geometry.r < settings.rest_speed
    detected[at_rest] = int(Mode.PARKING)
    table = np.array([""] + [Mode(m).label for m in range(1, len(Mode) + 1)], dtype=object)
    names = np.array(["mode " + x for x in table], dtype=object)
    return names[detected], table[detected]


def _chassis_velocity(geometry: Geometry, mode: Mode, alpha: np.ndarray, alpha_dot: np.ndarray,
                      beta_dot: np.ndarray) -> np.ndarray:
    """Chassis velocities (v_x, v_y, omega) of a run by odometry, eq. (3), at the filtered angles.

    Mode 1: the chassis rows of H_1 are zero, so the chassis velocities do not enter eq. (19)
    (neither directly nor through the Coriolis terms of eq. 16); zeros are returned.
    """
    if mode is Mode.PARKING:
        return np.zeros((alpha.shape[0], 3))
    return odometry(geometry, alpha, alpha_dot, beta_dot)


@dataclass(frozen=True)
class _Kinematics:
    """Filtered angles and derivatives of a stretch of a log."""

    dt: float
    alpha: np.ndarray
    alpha_dot: np.ndarray
    alpha_ddot: np.ndarray
    beta_dot: np.ndarray
    beta_ddot: np.ndarray


def _filtered_kinematics(t: np.ndarray, alpha: np.ndarray, beta: np.ndarray, settings: IdentificationSettings,
                         where: str) -> _Kinematics:
    dt = uniform_sample_time(t, rtol=settings.sample_jitter, source=f"{where}: column 't'")
    a, a_d, a_dd = filtered_derivatives(alpha, dt, settings.filter)
    a = np.clip(a, -math.pi / 2, math.pi / 2)  # the filter may overshoot the stops by round-off
    _, b_d, b_dd = filtered_derivatives(beta, dt, settings.filter)
    return _Kinematics(dt, a, a_d, a_dd, b_d, b_dd)


def _run_block(geometry: Geometry, mode: Mode, t: np.ndarray, kin: _Kinematics, sl: slice, u: np.ndarray,
               settings: IdentificationSettings, *, segment: str, source: str) -> EquationBlock:
    """Measured rows of one run: odometry, eq. (19), filtering of both sides, stiction mask."""
    a = kin.alpha[sl]
    chassis = _chassis_velocity(geometry, mode, a, kin.alpha_dot[sl], kin.beta_dot[sl])
    chassis_dd = time_derivative(chassis, kin.dt)
    q_dot = np.concatenate([chassis, kin.alpha_dot[sl], kin.beta_dot[sl]], axis=1)
    q_ddot = np.concatenate([chassis_dd, kin.alpha_ddot[sl], kin.beta_ddot[sl]], axis=1)
    u_used = lowpass(u, kin.dt, settings.filter) if settings.filtering is Filtering.LITERAL else u
    block = equation_block(geometry, mode, a, q_dot, q_ddot, u_used, t=t, segment=segment, source=source,
                           stiction_threshold=settings.thresholds(), epsilon=settings.epsilon,
                           mode_tolerance=settings.mode_tolerance)
    guard = int(round(settings.stiction_guard / settings.filter.cutoff / kin.dt))
    if guard:
        block = EquationBlock(source, segment, mode, t, block.regressor, block.torque, block.s_dot,
                              guarded_mask(block.keep, guard), block.offset_regressor)
    if settings.filtering is Filtering.PARALLEL:
        Y = parallel_filter(block.regressor, kin.dt, settings.filter)
        tau = parallel_filter(block.torque, kin.dt, settings.filter)
        offset = block.offset_regressor
        if mode is Mode.CAR_LIKE:  # constant in the other modes, where filtering leaves it unchanged
            offset = parallel_filter(offset, kin.dt, settings.filter)
        block = EquationBlock(source, segment, mode, t, Y, tau, block.s_dot, block.keep, offset)
    return block


def log_equations(log: Any, geometry: Geometry, settings: IdentificationSettings = IdentificationSettings()
                  ) -> tuple[list[EquationBlock], list[str]]:
    """Equation blocks of every usable run of a log, and notes on the runs skipped.

    With a ``segment`` column, every run of one segment name is filtered on its own (a segment
    boundary may be a jump between experiments) and is one run of its segment's mode. Without
    it, the whole log is filtered at once and the runs are the ranges of equal mode detected
    from the filtered steering angles (eq. 9). Runs excluded by the segment table, or too short
    for the zero-phase filter, are skipped with a note.
    """
    source = str(getattr(log, "path", None) or "<log>")
    t_all, alpha, beta, u = log.t, log.alpha, log.beta, log.torque
    padlen = settings.filter.padlen(float(np.median(np.diff(t_all))))
    labelled = _segment_runs(log, settings)
    if labelled is None:
        kin_all = _filtered_kinematics(t_all, alpha, beta, settings, source)
        names, labels = _detected_labels(geometry, kin_all, settings)
        pieces = [(a, b, str(names[a]), str(labels[a])) for a, b in runs(labels)]
    else:
        kin_all = None
        pieces = labelled
    blocks, notes = [], []
    for start, stop, name, label in pieces:
        if label == "":
            continue
        if stop - start <= padlen:
            notes.append(f"{source}: run {name!r} rows {start}..{stop - 1} skipped: {stop - start} "
                         f"samples, the zero-phase filter needs more than {padlen}")
            continue
        sl = slice(start, stop)
        if kin_all is None:  # a segment is filtered on its own
            kin, rows = _filtered_kinematics(t_all[sl], alpha[sl], beta[sl], settings,
                                             f"{source}: segment {name!r} from row {start}"), slice(None)
        else:
            kin, rows = kin_all, sl
        blocks.append(_run_block(geometry, Mode.from_label(label), t_all[sl], kin, rows, u[sl],
                                 settings, segment=name, source=source))
    return blocks, notes


def stacked_system(blocks: Sequence[EquationBlock], *, kept_only: bool = True, offsets: bool = False
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Stacked regressor ``Theta_hat`` (m, 11) and right-hand side ``tau_hat`` (m,) of eq. (22).

    ``offsets``: four more columns ``H_k^T B e_i`` for the motor-torque offsets (m, 15).
    """
    width = N_P + (4 if offsets else 0)
    if not blocks:
        return np.zeros((0, width)), np.zeros(0)

    def columns(b: EquationBlock) -> np.ndarray:
        full = np.concatenate([b.regressor, b.offset_regressor], axis=2) if offsets else b.regressor
        return full.reshape(-1, width)

    A = [columns(b)[b.keep.ravel()] if kept_only else columns(b) for b in blocks]
    y = [b.torque.ravel()[b.keep.ravel()] if kept_only else b.torque.ravel() for b in blocks]
    return np.concatenate(A), np.concatenate(y)


@dataclass(frozen=True)
class Dependency:
    """A parameter the data do not determine: its column is (numerically or nearly) a combination
    of the columns of others, or its estimate is dominated by noise."""

    name: str
    combination_of: tuple[str, ...]
    relative_residual: float
    inflation: float = math.nan
    relative_std: float = math.nan

    def describe(self) -> str:
        if math.isfinite(self.relative_std):
            how = f"its standard deviation is {100 * self.relative_std:.0f} % of its value: the data hardly excite it"
        elif math.isfinite(self.inflation):
            how = (f"its regressor column is nearly a combination of the others (variance inflation "
                   f"{self.inflation:.3g})")
        elif not self.combination_of:
            how = "its regressor column is zero: the data do not excite it"
        else:
            how = f"its regressor column is a combination of those of {', '.join(self.combination_of)}"
        excited_by = EXCITATION.get(self.name, "steering reversals in every segment (motor-torque offset)")
        return f"{self.name} ({how}; excited by {excited_by})"


class UnidentifiableError(ValueError):
    """The data do not excite some parameters; ``dependencies`` names them."""

    def __init__(self, dependencies: Sequence[Dependency], context: str = "") -> None:
        self.dependencies = tuple(dependencies)
        names = [d.name for d in self.dependencies]
        lines = "\n  ".join(d.describe() for d in self.dependencies)
        super().__init__(
            f"{context}parameters {names} cannot be identified from these data:\n  {lines}\n"
            f"add the experiments named above or fix the parameters as known (e.g. --fix {names[0]}=VALUE)"
        )


def _column_norms(A: np.ndarray) -> np.ndarray:
    """Euclidean norms of the columns of A (the diagonal of W^-1 in eq. 25)."""
    return np.sqrt(np.einsum("ij,ij->j", A, A))


def dependent_parameters(A: np.ndarray, names: Sequence[str], *, tolerance: float = 1e-6) -> list[Dependency]:
    """Parameters whose columns of the stacked regressor are not linearly independent (sec. 6.1).

    The QR test of :func:`agvdyn.identifiability.base_parameters_of` with the columns taken in
    the paper's order of representatives (m_ch, C_ch, d_vw, d_cw, C_l, ..., B_w), so that the
    parameter named as not identifiable is the one the paper treats as dependent.
    """
    names = list(names)
    base = base_parameters_of(A, names=names, order=_RANK_ORDER, tolerance=tolerance)
    out = [Dependency(n, (), 0.0) for n in base.unidentifiable]
    out += [Dependency(n, base.combination_of.get(n, ()), base.relative_r[n]) for n in base.dependent]
    return sorted(out, key=lambda d: names.index(d.name))


def variance_inflation(A: np.ndarray) -> np.ndarray:
    """Variance inflation factors ``diag((A_w^T A_w)^-1)`` of the unit-norm columns of A.

    1 for a column orthogonal to the others, large when it is nearly a combination of them.
    """
    R = triangular_factor(A / _column_norms(A))
    R_inv = scipy.linalg.solve_triangular(R, np.eye(R.shape[0]))
    return np.einsum("ij,ij->i", R_inv, R_inv)


class Estimator(ABC):
    """Interface of the estimators (scikit-learn style): settings in ``__init__``, ``fit`` returns
    self, fitted results end in ``_``.

    ``fit(A, y)`` takes the stacked regressor of the free parameters and the right-hand side of
    eq. (24) and sets ``coef_`` (values), ``cov_`` (covariance), ``condition_number_``.
    """

    coef_: np.ndarray
    cov_: np.ndarray
    condition_number_: float

    @abstractmethod
    def fit(self, A: np.ndarray, y: np.ndarray) -> "Estimator":
        ...

    @property
    def std_(self) -> np.ndarray:
        self._check_fitted()
        return np.sqrt(np.diag(self.cov_))

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise RuntimeError(f"{type(self).__name__} is not fitted: call fit(A, y) first")


class LeastSquares(Estimator):
    """Least squares with column scaling, eq. (25).

    ``Theta_1,w = Theta_1 W`` with ``W = diag(1 / ||theta_1,i||)`` (unit-norm columns; the extracted
    text says W "contains the norms", the reciprocal is the reading that improves the
    conditioning), ``p_1 = W Theta_1,w^+ (tau - Theta_2 p_2)`` by ``scipy.linalg.lstsq``.
    Covariance ``sigma^2 W (Theta_1,w^T Theta_1,w)^-1 W`` with ``sigma^2 = |r|^2 / (m - n)``.
    ``condition_number_`` is ``cond(Theta_1,w^T Theta_1,w)`` (the quantity the paper reports, 11.56),
    ``condition_number_unscaled_`` the same of the unscaled ``Theta_1``.
    """

    def fit(self, A: np.ndarray, y: np.ndarray) -> "LeastSquares":
        A = np.asarray(A, dtype=float)
        y = np.asarray(y, dtype=float)
        m, n = A.shape
        if m <= n:
            raise ValueError(f"least squares with {m} rows for {n} parameters: expected more rows than parameters")
        norms = _column_norms(A)
        if np.any(norms == 0):
            raise ValueError(f"columns {np.flatnonzero(norms == 0).tolist()} of the regressor are zero")
        # QR of [Theta_1,w | tau]: R_aug = [[R, Q^T tau], [0, |r|]] gives the solution, the residual
        # norm and (Theta_1,w^T Theta_1,w)^-1 = R^-1 R^-T without forming the normal equations.
        R_aug = triangular_factor(np.column_stack([A / norms, y]))
        R, qty, res_norm = R_aug[:n, :n], R_aug[:n, n], abs(R_aug[n, n])
        pw = scipy.linalg.solve_triangular(R, qty)
        R_inv = scipy.linalg.solve_triangular(R, np.eye(n))
        sigma2 = res_norm**2 / (m - n)
        sv = np.linalg.svd(R, compute_uv=False)
        self.scale_ = 1.0 / norms
        self.coef_ = pw / norms
        self.cov_ = sigma2 * (R_inv @ R_inv.T) / np.outer(norms, norms)
        self.sigma2_ = sigma2
        self.residual_norm_ = res_norm
        self.condition_number_ = float((sv[0] / sv[-1]) ** 2)
        sv_raw = np.linalg.svd(R * norms, compute_uv=False)  # R W^-1 is a triangular factor of Theta_1
        self.condition_number_unscaled_ = float((sv_raw[0] / sv_raw[-1]) ** 2)
        self.n_rows_ = m
        return self


@dataclass(frozen=True, eq=False)
class Identification:
    """Result of :func:`identify`: parameters with uncertainty and the data behind them.

    Attributes
    ----------
    parameters : all 11 parameters (fixed ones at their given values).
    std : standard deviation of each estimated parameter.
    fixed : names of the parameters taken as known (eq. 24).
    condition_number : ``cond(Theta_1,w^T Theta_1,w)`` of the column-scaled stacked regressor
        (the paper's 11.56); ``condition_number_unscaled`` of ``Theta_1^T Theta_1``.
    residual_rms : RMS of ``tau - Theta p`` over the kept rows, per ``"segment:coordinate"``.
    blocks : the equation blocks (Fig. 5 data), ``notes``: runs skipped and why.
    offsets, offsets_std : estimated motor-torque offsets (motor side, N m) when
        ``settings.torque_offsets``; the model torques of Fig. 5 include them.
        ``condition_number_with_offsets``: cond of the scaled regressor with the offset columns.
    """

    parameters: Parameters
    std: dict[str, float]
    fixed: tuple[str, ...]
    condition_number: float
    condition_number_unscaled: float
    residual_rms: dict[str, float]
    n_rows: int
    n_samples: int
    blocks: tuple[EquationBlock, ...]
    settings: IdentificationSettings
    geometry: Geometry
    sources: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    estimator: str = "LeastSquares"
    offsets: dict[str, float] = field(default_factory=dict)
    offsets_std: dict[str, float] = field(default_factory=dict)
    condition_number_with_offsets: float = float("nan")

    @property
    def offset_vector(self) -> np.ndarray | None:
        """Motor-torque offsets (4,) in wheel order, None when they were not estimated."""
        return np.array([self.offsets[n] for n in OFFSET_NAMES]) if self.offsets else None

    def to_frame(self) -> pd.DataFrame:
        """Parameter table: value, std, relative std, unit, fixed; index = parameter name."""
        rows = []
        for name in PARAMETER_NAMES:
            value = getattr(self.parameters, name)
            std = self.std.get(name, float("nan"))
            rows.append({"name": name, "value": value, "std": std,
                         "rel_std": std / abs(value) if value != 0 else float("nan"),
                         "unit": PARAMETER_UNITS[name], "fixed": name in self.fixed})
        return pd.DataFrame(rows).set_index("name")

    def torques_frame(self) -> pd.DataFrame:
        """Measured and model generalized torques per row (long format, Fig. 5)."""
        p = self.parameters.to_vector()
        frames = []
        for b in self.blocks:
            model = b.model_torque(p, self.offset_vector)
            for j, coord in enumerate(b.coordinates):
                frames.append(pd.DataFrame({
                    "source": b.source, "segment": b.segment, "mode": b.mode.label, "coordinate": coord,
                    "t": b.t, "measured": b.torque[:, j], "model": model[:, j], "kept": b.keep[:, j]}))
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def to_parameter_file(self) -> ParameterFile:
        extra = {
            "condition_number_unscaled": self.condition_number_unscaled,
            "residual_rms": dict(self.residual_rms),
            "n_rows": self.n_rows,
            "n_samples": self.n_samples,
            "estimator": self.estimator,
            "settings": self.settings.to_dict(),
            "platform": self.geometry.to_dict(),
            "sources": list(self.sources),
            "torque_offsets": {n: {"value": v, "std": self.offsets_std.get(n)} for n, v in self.offsets.items()},
        }
        return ParameterFile(self.parameters, dict(self.std), self.fixed, self.condition_number, extra)

    def write(self, path: str | os.PathLike) -> Path:
        """Write the parameter file (YAML, or JSON by suffix) atomically."""
        return write_parameters(path, self.to_parameter_file())

    def to_json_dict(self) -> dict[str, Any]:
        """The summary printed by ``agvdyn identify --json``."""
        return {
            "parameters": {n: {"value": getattr(self.parameters, n), "std": self.std.get(n)} for n in PARAMETER_NAMES},
            "condition_number": self.condition_number,
            "condition_number_unscaled": self.condition_number_unscaled,
            "condition_number_with_offsets": (None if not math.isfinite(self.condition_number_with_offsets)
                                              else self.condition_number_with_offsets),
            "fixed": list(self.fixed),
            "residual_rms": dict(self.residual_rms),
            "torque_offsets": {n: {"value": v, "std": self.offsets_std.get(n)} for n, v in self.offsets.items()},
            "n_rows": self.n_rows,
            "n_samples": self.n_samples,
            "filtering": self.settings.filtering.value,
            "sources": list(self.sources),
            "notes": list(self.notes),
        }


def load_logs(logs: Any, *, mapping: Any = None, platform: Geometry | str | os.PathLike | None = None) -> list[Any]:
    """Logs as :class:`agvdyn.io.Log` objects: paths are loaded and checked with
    ``agvdyn.io.load_log(path, mapping, platform)`` (mapping: for tables and bags not in our
    schema), Log objects are passed through."""
    from agvdyn.io import load_log

    if isinstance(logs, (str, os.PathLike)) or hasattr(logs, "alpha"):
        logs = [logs]
    out = [load_log(x, mapping, platform) if isinstance(x, (str, os.PathLike)) else x for x in logs]
    if not out:
        raise ValueError("no logs given: expected at least one log")
    return out


def platform_for(logs: Sequence[Any], platform: Geometry | str | os.PathLike | None) -> Geometry:
    """The geometry to use: the one given, else the ``platform`` of the first log's sidecar, else PROTOTYPE."""
    from agvdyn.io import sidecar_platform

    if isinstance(platform, Geometry):
        return platform
    if platform is not None:
        return read_platform(platform)
    for log in logs:
        if getattr(log, "sidecar", None):
            found = sidecar_platform(log)
            if found is not None:
                return found
    return PROTOTYPE


def _check_fixed(fixed: Mapping[str, float]) -> dict[str, float]:
    out = {}
    for name, value in fixed.items():
        if name not in PARAMETER_NAMES:
            raise ValueError(f"fixed parameter {name!r}: expected one of {list(PARAMETER_NAMES)}")
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"fixed parameter {name}={value!r}: expected a finite number")
        out[name] = float(value)
    if len(out) == len(PARAMETER_NAMES):
        raise ValueError("every parameter is fixed: nothing to identify")
    return out


def _residual_rms(blocks: Sequence[EquationBlock], p: np.ndarray, offsets: np.ndarray | None = None
                  ) -> dict[str, float]:
    """RMS of tau - Theta p over the kept rows per "segment:coordinate" (runs of equal name pooled);
    coordinates with no kept row (e.g. the resting side while the other one steers) are left out."""
    sums: dict[str, list[float]] = {}
    for b in blocks:
        r = b.torque - b.model_torque(p, offsets)
        for j, coord in enumerate(b.coordinates):
            sel = r[b.keep[:, j], j]
            if sel.size:
                acc = sums.setdefault(f"{b.segment}:{coord}", [0.0, 0])
                acc[0] += float(sel @ sel)
                acc[1] += sel.size
    return {k: math.sqrt(s / n) for k, (s, n) in sums.items()}


def fit_blocks(blocks: Sequence[EquationBlock], geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
               settings: IdentificationSettings = IdentificationSettings(), estimator: Estimator | None = None,
               sources: Iterable[str] = (), notes: Iterable[str] = (), n_samples: int | None = None) -> Identification:
    """Regression stage: stack the blocks (eq. 22), fixed parameters to the right (eq. 24), rank
    check naming what is not excited, scaled least squares (eq. 25)."""
    fixed = _check_fixed(fixed)
    blocks = tuple(blocks)
    with_offsets = settings.torque_offsets
    A, y = stacked_system(blocks, offsets=with_offsets)
    names = list(PARAMETER_NAMES) + (list(OFFSET_NAMES) if with_offsets else [])
    free = [n for n in names if n not in fixed]
    idx_free = [names.index(n) for n in free]
    p_fixed = np.zeros(len(names))
    for name, value in fixed.items():
        p_fixed[names.index(name)] = value
    if A.shape[0] <= len(free):
        raise UnidentifiableError(
            [Dependency(n, (), 0.0) for n in free],
            f"{A.shape[0]} equation rows left after the stiction mask for {len(free)} parameters; ")
    y1 = y - A @ p_fixed  # eq. (24)
    A1 = A[:, idx_free]
    missing = dependent_parameters(A1, free, tolerance=settings.rank_tolerance)
    if missing:
        raise UnidentifiableError(missing)
    inflation = variance_inflation(A1)
    collinear = [Dependency(n, (), math.nan, inflation=float(v)) for n, v in zip(free, inflation)
                 if v > settings.max_inflation and n in PARAMETER_NAMES]
    if collinear:
        raise UnidentifiableError(collinear, f"poorly conditioned data (variance inflation above "
                                             f"{settings.max_inflation:g}): ")
    est = (estimator if estimator is not None else LeastSquares()).fit(A1, y1)
    noisy = [Dependency(n, (), math.nan, relative_std=float(sd / abs(v)))
             for n, v, sd in zip(free, est.coef_, est.std_)
             if n in PARAMETER_NAMES and sd > settings.max_relative_std * abs(v)]
    if noisy:
        raise UnidentifiableError(noisy, f"weakly excited data (standard deviation above "
                                         f"{100 * settings.max_relative_std:g} % of the value): ")
    # cond(Theta_1,w^T Theta_1,w) of the paper's parameters alone (eq. 25); the nuisance offset
    # columns are reported separately
    param_cols = [i for i, n in enumerate(free) if n in PARAMETER_NAMES]
    if len(param_cols) < len(free):
        cond_with_offsets = float(est.condition_number_)
        R = triangular_factor(A1[:, param_cols] / _column_norms(A1[:, param_cols]))
        sv = np.linalg.svd(R, compute_uv=False)
        cond = float((sv[0] / sv[-1]) ** 2)
        sv_raw = np.linalg.svd(R * _column_norms(A1[:, param_cols]), compute_uv=False)
        cond_unscaled = float((sv_raw[0] / sv_raw[-1]) ** 2)
    else:
        cond = float(est.condition_number_)
        cond_unscaled = float(getattr(est, "condition_number_unscaled_", float("nan")))
        cond_with_offsets = float("nan")
    theta = p_fixed.copy()
    theta[idx_free] = est.coef_
    p = theta[:N_P]
    offsets = theta[N_P:] if with_offsets else None
    all_std = dict(zip(free, est.std_.tolist()))
    std = {n: v for n, v in all_std.items() if n in PARAMETER_NAMES}
    residual_rms = _residual_rms(blocks, p, offsets)
    return Identification(
        parameters=Parameters.from_vector(p), std=std, fixed=tuple(n for n in PARAMETER_NAMES if n in fixed),
        condition_number=cond, condition_number_unscaled=cond_unscaled,
        condition_number_with_offsets=cond_with_offsets,
        residual_rms=residual_rms, n_rows=int(A.shape[0]),
        n_samples=int(n_samples if n_samples is not None else sum(b.t.size for b in blocks)),
        blocks=blocks, settings=settings, geometry=geometry, sources=tuple(sources), notes=tuple(notes),
        estimator=type(est).__name__,
        offsets={} if offsets is None else dict(zip(OFFSET_NAMES, offsets.tolist())),
        offsets_std={n: all_std[n] for n in OFFSET_NAMES if n in all_std})


def identify(logs: Any, platform: Geometry | str | os.PathLike | None = None, *,
             fixed: Mapping[str, float] = DEFAULT_FIXED,
             settings: IdentificationSettings = IdentificationSettings(),
             estimator: Estimator | None = None) -> Identification:
    """Identify the dynamic parameters p (eq. 18) from one or more logs, eq. (22)-(25).

    Parameters
    ----------
    logs : path, Log, or a sequence of them (paths are read with :func:`agvdyn.io.load_log`).
    platform : Geometry or platform file; default the sidecar's platform, else the prototype.
    fixed : parameters taken as known (eq. 24), default ``{"B_w": 0.121}``.
    settings : :class:`IdentificationSettings`.
    estimator : an :class:`Estimator`, default :class:`LeastSquares`.

    Raises
    ------
    UnidentifiableError
        When the data do not excite some free parameter (message names it and the experiment
        that would excite it).
    """
    logs = load_logs(logs)
    geometry = platform_for(logs, platform)
    blocks, notes = [], []
    for log in logs:
        b, n = log_equations(log, geometry, settings)
        blocks += b
        notes += n
    if not blocks:
        raise ValueError(
            "no usable rows: the logs contain no run in a motion mode "
            f"(segments used: {settings.segments or 'all with a mode'})")
    sources = [str(getattr(log, "path", None) or "<log>") for log in logs]
    return fit_blocks(blocks, geometry, fixed=fixed, settings=settings, estimator=estimator, sources=sources,
                      notes=notes, n_samples=sum(len(log.t) for log in logs))
