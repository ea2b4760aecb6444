"""Rows of eq. (19): ``H_k^T Theta p = H_k^T B u`` per sample and generalized coordinate."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from agvdyn.dynamics import project_signals, projected_input, projected_regressor
from agvdyn.identification.model_rows import resolved_model
from agvdyn.kinematics import MODE_TOLERANCE, Mode, kinematic_model
from agvdyn.model_spec import PAPER_MODEL, ModelSpec, breakaway_weight
from agvdyn.platform import EPSILON, PARAMETER_NAMES, Geometry
from agvdyn.signals import stiction_mask

__all__ = ["EquationBlock", "equation_block", "projected_block", "generalized_velocity", "model_columns"]


@dataclass(frozen=True, eq=False)
class EquationBlock:
    """Rows of eq. (19) for consecutive samples in one motion mode.

    Attributes
    ----------
    source, segment : where the rows come from (file name; segment label, or ``"mode k"``).
    mode : motion mode k of the rows.
    t : (n,) time, s.
    regressor : (n, n_k, 11) ``H_k^T Theta`` as used in the regression (filtered when set so).
    torque : (n, n_k) ``H_k^T B u`` as used in the regression.
    s_dot : (n, n_k) generalized velocities (eq. 10-13).
    keep : (n, n_k) rows used in the regression (stiction, slip, edges and guards dropped).
    offset_regressor : (n, n_k, 4) ``H_k^T B e_i``: generalized torques of a unit offset of each
        motor-torque measurement.
    recording : name of the continuous recording the rows come from (residuals are correlated
        within one, independent between two); ``sample`` (n,) the rows' sample index in it.
    model_regressor : (n, n_k, q) the columns a model extension adds, in the order of
        :attr:`agvdyn.model_spec.ModelSpec.linear_names` (breakaway levels ``d_s``, then ``m_ch x_c``,
        ``m_ch y_c``), or None (the paper's model). With the breakaway columns, the ``d_c`` columns of
        ``regressor`` are ``H_k^T [(1 - e) tanh]``: the model torque needs both.
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
    recording: str = ""
    sample: np.ndarray | None = None
    model_regressor: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.sample is None:
            object.__setattr__(self, "sample", np.arange(self.t.size))
        if not self.recording:
            object.__setattr__(self, "recording", f"{self.source}:{self.segment}")

    @property
    def coordinates(self) -> tuple[str, ...]:
        return self.mode.coordinates

    def model_torque(self, p: np.ndarray, offsets: np.ndarray | None = None,
                     extra: np.ndarray | None = None) -> np.ndarray:
        """Model generalized torques ``H_k^T Theta p`` (n, n_k), plus ``H_k^T B o`` of motor-torque
        offsets ``o`` (4,) when given (the model of the *measured* torques), plus the model
        extension's columns times their values ``extra`` (q,) when the block has them."""
        out = self.regressor @ np.asarray(p, dtype=float)
        if offsets is not None:
            out = out + self.offset_regressor @ np.asarray(offsets, dtype=float)
        if extra is not None and self.model_regressor is not None:
            out = out + self.model_regressor @ np.asarray(extra, dtype=float)
        return out

    def rows(self, sl: slice, segment: str) -> "EquationBlock":
        """The rows ``sl`` of this block under another segment name."""
        return EquationBlock(self.source, segment, self.mode, self.t[sl], self.regressor[sl], self.torque[sl],
                             self.s_dot[sl], self.keep[sl], self.offset_regressor[sl], self.recording, self.sample[sl],
                             None if self.model_regressor is None else self.model_regressor[sl])

    def with_keep(self, keep: np.ndarray) -> "EquationBlock":
        return EquationBlock(self.source, self.segment, self.mode, self.t, self.regressor, self.torque, self.s_dot,
                             keep, self.offset_regressor, self.recording, self.sample, self.model_regressor)


def generalized_velocity(H: np.ndarray, q_dot: np.ndarray) -> np.ndarray:
    """s_dot = H^+ q_dot (least squares on the kinematic model of eq. 4), (n, n_k)."""
    if H.strides[0] == 0:  # constant model broadcast over samples
        return q_dot @ np.linalg.pinv(H[0]).T
    normal = np.einsum("nik,nij->nkj", H, H)
    rhs = np.einsum("nik,ni->nk", H, q_dot)
    return np.linalg.solve(normal, rhs[..., None])[..., 0]


def _thresholds(mode: Mode, stiction_threshold: float | Mapping[str, float]) -> float | np.ndarray:
    if isinstance(stiction_threshold, Mapping):
        return np.array([stiction_threshold[c] for c in mode.coordinates])
    return stiction_threshold


def _offset_columns(geometry: Geometry, H: np.ndarray, n: int) -> np.ndarray:
    """``H_k^T B e_i`` (n, n_k, 4) for the four unit motor-torque offsets."""
    return np.broadcast_to(geometry.i_G * np.swapaxes(H[:, 5:, :], 1, 2), (n, H.shape[2], 4))


def equation_block(geometry: Geometry, mode: Mode | str, alpha: np.ndarray, q_dot: np.ndarray,
                   q_ddot: np.ndarray, u: np.ndarray, *, t: np.ndarray | None = None, segment: str = "",
                   source: str = "", stiction_threshold: float | Mapping[str, float] = 0.0, epsilon: float = EPSILON,
                   mode_tolerance: float = MODE_TOLERANCE, model: ModelSpec = PAPER_MODEL) -> EquationBlock:
    """Rows ``H_k^T Theta(q, q_dot, q_ddot)`` and ``H_k^T B u`` of eq. (19) from given joint motion.

    No filtering: the signals are used as given (exact model signals, or already filtered
    measurements). Rows with ``|s_dot| < stiction_threshold`` are marked not kept; the threshold
    is one number or one per coordinate name (``mode.coordinates``). ``model``: a resolved
    :class:`~agvdyn.model_spec.ModelSpec`; its columns (:func:`model_columns`) come with the rows.
    """
    mode = Mode.from_label(mode)
    model = resolved_model(model)
    alpha = np.asarray(alpha, dtype=float)
    n = alpha.shape[0]
    try:
        H = kinematic_model(geometry, mode, alpha, tolerance=mode_tolerance)
        Y = projected_regressor(geometry, mode, alpha, q_dot, q_ddot, epsilon=epsilon, tolerance=mode_tolerance)
        tau = projected_input(geometry, mode, alpha, u, tolerance=mode_tolerance)
    except ValueError as exc:
        where = f"{source}: " if source else ""
        raise ValueError(f"{where}segment {segment!r} (mode {mode.label}): {exc}") from exc
    s_dot = generalized_velocity(H, np.asarray(q_dot, dtype=float))
    keep = stiction_mask(s_dot, _thresholds(mode, stiction_threshold))
    t = np.arange(n, dtype=float) if t is None else np.asarray(t, dtype=float)
    X = model_columns(H, q_dot, q_ddot, model, Y, epsilon, mode) if model.linear_names else None
    return EquationBlock(source, segment, mode, t, Y, tau, s_dot, keep, _offset_columns(geometry, H, n),
                         model_regressor=X)


def model_columns(H: np.ndarray, q_dot: np.ndarray, q_ddot: np.ndarray, model: ModelSpec, Y: np.ndarray,
                  epsilon: float = EPSILON, mode: Mode = Mode.CAR_LIKE) -> np.ndarray:
    """The columns ``model.linear_names`` (n, n_k, q) of the model extensions (:mod:`agvdyn.model_spec`)
    from unfiltered joint motion in ``mode``, projected by ``H`` (n or 1, 9, n_k): ``H_k^T [e tanh]`` per
    joint group (``e = exp(-(w/w_s)^2)``; the ``d_c`` columns of ``Y`` (n, n_k, 11) lose that share, in
    place), then ``m_ch x_c`` (chassis rows ``-w^2, w_dot, a_y``) and ``m_ch y_c`` (``-w_dot, -w^2, -a_x``),
    zero but in car-like motion (as the row pass, :mod:`.model_rows`)."""
    qd, qdd = np.asarray(q_dot, dtype=float), np.asarray(q_ddot, dtype=float)
    H = np.broadcast_to(H, (qd.shape[0], *H.shape[1:]))
    cols = []
    if model.stribeck:
        w_sl, w_sr, w_sw = model.stribeck_velocities
        rates = qd[:, 3:9]
        share = breakaway_weight(rates, np.array([w_sl, w_sr, w_sw, w_sw, w_sw, w_sw])) * np.tanh(rates / epsilon)
        groups = (H[:, 3, :] * share[:, :1], H[:, 4, :] * share[:, 1:2],
                  np.einsum("nwk,nw->nk", H[:, 5:, :], share[:, 2:]))
        for name, col in zip(("d_cl", "d_cr", "d_cw"), groups):
            Y[:, :, PARAMETER_NAMES.index(name)] -= col
        cols += groups
    if model.com_offset and mode is not Mode.CAR_LIKE:  # no rotation with translation (see .model_rows)
        cols += [np.zeros(H.shape[::2]), np.zeros(H.shape[::2])]
    elif model.com_offset:
        w, w_dot = qd[:, 2:3], qdd[:, 2:3]
        a_x, a_y = qdd[:, :1] - qd[:, 1:2] * w, qdd[:, 1:2] + qd[:, :1] * w
        cols.append(-H[:, 0, :] * w**2 + H[:, 1, :] * w_dot + H[:, 2, :] * a_y)
        cols.append(-H[:, 0, :] * w_dot - H[:, 1, :] * w**2 - H[:, 2, :] * a_x)
    return np.stack(cols, axis=2)


def projected_block(geometry: Geometry, mode: Mode, alpha: np.ndarray, q_dot: np.ndarray, signals: np.ndarray,
                    u: np.ndarray, *, t: np.ndarray, source: str, segment: str,
                    stiction_threshold: float | Mapping[str, float], mode_tolerance: float,
                    recording: str, sample: np.ndarray) -> EquationBlock:
    """Rows of eq. (19) from the (filtered) entries of Theta and torques of consecutive samples in mode k."""
    H = kinematic_model(geometry, mode, alpha, tolerance=mode_tolerance)
    n = alpha.shape[0]
    Y = project_signals(H, signals)
    tau = geometry.i_G * np.einsum("nik,ni->nk", H[:, 5:, :], u)
    s_dot = generalized_velocity(H, q_dot)
    keep = stiction_mask(s_dot, _thresholds(mode, stiction_threshold))
    return EquationBlock(source, segment, mode, t, Y, tau, s_dot, keep, _offset_columns(geometry, H, n),
                         recording, sample)
