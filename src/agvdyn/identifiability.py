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
    (``p_B = sum coefficient * p``); combination_of: for each dependent parameter, the
    representatives its column is a combination of; relative_r: |R_ii| / ||theta_i|| of every column.
    """

    modes: tuple[Mode, ...]
    rank: int
    identifiable: tuple[str, ...]
    dependent: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    groups: dict[str, dict[str, float]]
    combination_of: dict[str, tuple[str, ...]]
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
            "combination_of": {k: list(v) for k, v in self.combination_of.items()},
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


def triangular_factor(Y: np.ndarray, chunk: int = 8192) -> np.ndarray:
    """R of ``Y = Q R`` ``(n, n)`` by a tall-skinny QR: QR of row blocks, then of the stacked R's.

    Same R (up to row signs) as one Householder QR of Y, fast for millions of rows.
    """
    parts = [np.linalg.qr(Y[i:i + chunk], mode="r") for i in range(0, Y.shape[0], chunk)]
    return np.linalg.qr(np.vstack(parts), mode="r")


def base_parameters_of(regressor: np.ndarray, *, tolerance: float = QR_TOLERANCE,
                       names: Sequence[str] = PARAMETER_NAMES, order: Sequence[str] | None = None,
                       modes: tuple[Mode, ...] = ()) -> BaseParameters:
    """Base parameters of a stacked regressor ``(rows, n)`` by QR without pivoting (Gautier 1991).

    Columns are scaled to unit norm and taken in ``order`` (names; default: as given, which is
    eq. (18)); a column whose part orthogonal to the columns before it is at most ``tolerance`` is
    dependent, and the first column of each group becomes the group's representative.
    """
    Y = np.asarray(regressor, dtype=float)
    names = list(names)
    if Y.ndim != 2 or Y.shape[1] != len(names):
        raise ValueError(f"regressor of shape {Y.shape}: expected (rows, {len(names)})")
    if not tolerance > 0:
        raise ValueError(f"tolerance={tolerance!r}: expected > 0")
    rank_of = {n: i for i, n in enumerate(order)} if order is not None else {}
    norms = np.sqrt(np.einsum("ij,ij->j", Y, Y))
    # zero columns stay out of the QR: without pivoting they would take a Householder step (a row)
    # that the next column needs
    perm = sorted((i for i in range(len(names)) if norms[i] > 0), key=lambda i: rank_of.get(names[i], len(rank_of)))
    scale = np.where(norms > 0, norms, 1.0)
    R = triangular_factor((Y / scale)[:, perm])
    relative = np.zeros(len(names))
    relative[perm] = np.abs(np.diag(R))
    relative[norms == 0] = 0.0
    position = {j: k for k, j in enumerate(perm)}
    indep = [j for j in perm if relative[j] > tolerance]
    zero = sorted(j for j in range(len(names)) if norms[j] == 0)
    regrouped = sorted(j for j in range(len(names)) if relative[j] <= tolerance and norms[j] > 0)
    groups = {names[j]: {names[j]: 1.0} for j in indep}
    combination: dict[str, tuple[str, ...]] = {}
    if regrouped and indep:
        R_i = R[:, [position[j] for j in indep]]
        kappa_scaled = np.linalg.lstsq(R_i, R[:, [position[d] for d in regrouped]], rcond=None)[0]
        kappa = kappa_scaled / scale[indep][:, None] * scale[regrouped][None, :]
        for b, d in enumerate(regrouped):
            members = []
            for a, j in enumerate(indep):
                if abs(kappa_scaled[a, b]) > 1e-3:
                    groups[names[j]][names[d]] = float(np.round(kappa[a, b], 12))
                    members.append(j)
            combination[names[d]] = tuple(names[j] for j in sorted(members))
    return BaseParameters(
        modes=modes,
        rank=len(indep),
        identifiable=tuple(names[j] for j in sorted(indep)),
        dependent=tuple(names[j] for j in regrouped),
        unidentifiable=tuple(names[j] for j in zero),
        groups=groups,
        combination_of=combination,
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
