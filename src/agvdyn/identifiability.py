"""Identifiability: base parameters of a set of motion modes by QR decomposition (sec. 6.1, 6.3).

The stacked regressor of eq. (22) is filled with random motions of each mode and decomposed
``Theta = Q R`` (Gautier 1991) with the columns in the order of eq. (18). A column whose
``|R_ii|`` is at most ``tolerance`` times its own norm adds nothing to the columns before it:
its parameter is dependent and is regrouped into the base parameters
``p_B = p_1 + kappa p_2`` (sec. 6.3).
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from agvdyn.dynamics import projected_regressor
from agvdyn.kinematics import Mode, joint_motion, max_virtual_angle, nominal_steering, steering_from_virtual
from agvdyn.platform import EPSILON, PARAMETER_NAMES, Geometry

#: Relative size of |R_ii| below which a column counts as dependent. Structural dependences give
#: ~1e-16; independent columns of random motions ~1e-1. The separation of d_cw from d_cl, d_cr in
#: mode 1 only through the tanh scale (wheel rate = a/r times steering rate) gives a few 1e-2:
#: any tolerance below that (the default) calls d_cw identifiable in mode 1, any above merges it.
QR_TOLERANCE = 1e-6

#: The rows of Table 1 of the paper.
TABLE1_ROWS: tuple[tuple[Mode, ...], ...] = (
    (Mode.PARKING,), (Mode.CAR_LIKE,), (Mode.LATERAL,), (Mode.ROTATION,), (Mode.STRAIGHT,),
    (Mode.PARKING, Mode.STRAIGHT, Mode.ROTATION),
)


@dataclass(frozen=True)
class BaseParameters:
    """Result of the identifiability analysis of a set of modes.

    identifiable: parameters whose columns are independent (one representative per base parameter);
    dependent: parameters regrouped into them; unidentifiable: parameters with no effect at all;
    groups: for each representative, the coefficients of the parameters it stands for
    (``p_B = sum coefficient * p``); relative_r: |R_ii| / ||theta_i|| of every column.
    """

    modes: tuple[Mode, ...]
    rank: int
    identifiable: tuple[str, ...]
    dependent: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    groups: dict[str, dict[str, float]]
    relative_r: dict[str, float]
    tolerance: float

    def to_dict(self) -> dict:
        return {
            "modes": [m.label for m in self.modes],
            "rank": self.rank,
            "identifiable": list(self.identifiable),
            "dependent": list(self.dependent),
            "unidentifiable": list(self.unidentifiable),
            "groups": self.groups,
            "relative_r": self.relative_r,
            "tolerance": self.tolerance,
        }


def parse_modes(text: str | Iterable) -> tuple[Mode, ...]:
    """Modes from ``"1,2s,4"`` or an iterable of labels."""
    items = [s for s in text.split(",") if s.strip()] if isinstance(text, str) else list(text)
    if not items:
        raise ValueError(f"modes {text!r}: expected a comma-separated list such as 1,2s,4")
    return tuple(dict.fromkeys(Mode.from_label(s) for s in items))


def random_mode_regressor(geom: Geometry, mode: Mode, n_samples: int, rng: np.random.Generator,
                          epsilon: float = EPSILON) -> np.ndarray:
    """H_k^T Theta ``(n_samples * n_k, 11)`` at random configurations and motions of one mode (sec. 6.1).

    Mode 1: independent random steering angles; mode 2: random alpha_v and alpha from eq. (8);
    otherwise the mode's fixed angles. Generalized velocities and accelerations are standard normal.
    """
    mode = Mode.from_label(mode)
    if mode is Mode.PARKING:
        alpha = rng.uniform(-np.pi / 2, np.pi / 2, (n_samples, 2))
    elif mode is Mode.CAR_LIKE:
        alpha = steering_from_virtual(geom, rng.uniform(-0.95, 0.95, n_samples) * max_virtual_angle(geom))
    else:
        alpha = np.tile(nominal_steering(geom, mode), (n_samples, 1))
    s_dot = rng.standard_normal((n_samples, mode.dof))
    s_ddot = rng.standard_normal((n_samples, mode.dof))
    q_dot, q_ddot = joint_motion(geom, mode, alpha, s_dot, s_ddot)
    return projected_regressor(geom, mode, alpha, q_dot, q_ddot, epsilon=epsilon).reshape(-1, len(PARAMETER_NAMES))


def base_parameters_of(regressor: np.ndarray, *, tolerance: float = QR_TOLERANCE,
                       names: Sequence[str] = PARAMETER_NAMES, modes: tuple[Mode, ...] = ()) -> BaseParameters:
    """Base parameters of a stacked regressor ``(rows, 11)`` by QR without pivoting (Gautier 1991)."""
    Y = np.asarray(regressor, dtype=float)
    if Y.ndim != 2 or Y.shape[1] != len(names):
        raise ValueError(f"regressor of shape {Y.shape}: expected (rows, {len(names)})")
    if not tolerance > 0:
        raise ValueError(f"tolerance={tolerance!r}: expected > 0")
    norms = np.linalg.norm(Y, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    R = scipy.linalg.qr(Y / scale, mode="r")[0]
    diag = np.abs(np.diag(R[: Y.shape[1], : Y.shape[1]]))
    relative = np.where(norms > 0, diag, 0.0)
    indep = np.flatnonzero(relative > tolerance)
    dep = np.flatnonzero(relative <= tolerance)
    zero = [j for j in dep if norms[j] <= 1e-12 * max(norms.max(), 1e-300)]
    regrouped = [j for j in dep if j not in zero]
    groups = {names[j]: {names[j]: 1.0} for j in indep}
    if regrouped and len(indep):
        kappa = np.linalg.lstsq(Y[:, indep], Y[:, regrouped], rcond=None)[0]
        for a, j in enumerate(indep):
            for b, d in enumerate(regrouped):
                if abs(kappa[a, b]) > 1e-8:
                    groups[names[j]][names[d]] = float(np.round(kappa[a, b], 12))
    return BaseParameters(
        modes=modes,
        rank=len(indep),
        identifiable=tuple(names[j] for j in indep),
        dependent=tuple(names[j] for j in regrouped),
        unidentifiable=tuple(names[j] for j in zero),
        groups=groups,
        relative_r={names[j]: float(relative[j]) for j in range(len(names))},
        tolerance=tolerance,
    )


def base_parameters(geom: Geometry, modes, *, n_samples: int = 400, seed: int = 0,
                    tolerance: float = QR_TOLERANCE, epsilon: float = EPSILON) -> BaseParameters:
    """Base parameters identifiable from the motion modes ``modes`` (Table 1, sec. 6.1 and 6.3)."""
    modes = parse_modes(modes) if isinstance(modes, str) else tuple(Mode.from_label(m) for m in modes)
    rng = np.random.default_rng(seed)
    Y = np.concatenate([random_mode_regressor(geom, m, n_samples, rng, epsilon) for m in modes])
    return base_parameters_of(Y, tolerance=tolerance, modes=modes)


def table1(geom: Geometry, **kwargs) -> list[BaseParameters]:
    """The rows of Table 1 of the paper."""
    return [base_parameters(geom, row, **kwargs) for row in TABLE1_ROWS]
