"""Stage 3: the stacked regression of eq. (22)-(25), the rank and quality checks, estimators."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agvdyn.dynamics import N_P
from agvdyn.identifiability import base_parameters_of, triangular_factor
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.estimators import Estimator, LeastSquares, column_norms, solve_upper_triangular
from agvdyn.identification.settings import EXCITATION, OFFSET_NAMES
from agvdyn.identification.uncertainty import RowIndex

__all__ = ["stacked_system", "stacked_rows", "Dependency", "UnidentifiableError", "dependent_parameters",
           "variance_inflation", "column_norms", "Estimator", "LeastSquares"]

#: Order in which the rank check accepts columns: the representative the paper names for each
#: group of parameters that multiply the same signal comes first (Table 1: C_ch in rotation,
#: m_ch in straight motion), B_w last (the paper's dependent parameter p_2, sec. 6.3).
_RANK_ORDER = ("m_ch", "C_ch", "d_vw", "d_cw", "C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr", "B_w", *OFFSET_NAMES)


def stacked_system(blocks: Sequence[EquationBlock], *, kept_only: bool = True, offsets: bool = False
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Stacked regressor ``Theta_hat`` (m, 11) and right-hand side ``tau_hat`` (m,) of eq. (22).

    ``offsets``: four more columns ``H_k^T B e_i`` for the motor-torque offsets (m, 15); blocks with a
    model extension's columns (``model_regressor``, :mod:`agvdyn.model_spec`) add those last.
    """
    model = 0 if not blocks or blocks[0].model_regressor is None else blocks[0].model_regressor.shape[2]
    width = N_P + (4 if offsets else 0) + model
    if not blocks:
        return np.zeros((0, width)), np.zeros(0)

    def columns(b: EquationBlock) -> np.ndarray:
        parts = [b.regressor, *([b.offset_regressor] if offsets else []),
                 *([] if b.model_regressor is None else [b.model_regressor])]
        full = np.concatenate(parts, axis=2) if len(parts) > 1 else b.regressor
        return full.reshape(-1, width)

    A = [columns(b)[b.keep.ravel()] if kept_only else columns(b) for b in blocks]
    y = [b.torque.ravel()[b.keep.ravel()] if kept_only else b.torque.ravel() for b in blocks]
    return np.concatenate(A), np.concatenate(y)


def stacked_rows(blocks: Sequence[EquationBlock], *, offsets: bool = False) -> tuple[np.ndarray, np.ndarray, RowIndex]:
    """The kept rows of eq. (22) as :func:`stacked_system`, with where each row comes from."""
    A, y = stacked_system(blocks, offsets=offsets)
    names: dict[str, int] = {}
    recordings: dict[str, int] = {}
    group, recording, step = [], [], []
    for b in blocks:
        keep = b.keep
        codes = np.array([names.setdefault(c, len(names)) for c in b.coordinates])
        rec = recordings.setdefault(b.recording, len(recordings))
        group.append(np.broadcast_to(codes, keep.shape)[keep])
        recording.append(np.full(int(keep.sum()), rec))
        step.append(np.broadcast_to(b.sample[:, None], keep.shape)[keep])
    index = RowIndex(np.concatenate(group).astype(np.int64) if group else np.zeros(0, np.int64), tuple(names),
                     np.concatenate(recording).astype(np.int64) if recording else np.zeros(0, np.int64),
                     np.concatenate(step).astype(np.int64) if step else np.zeros(0, np.int64))
    return A, y, index


@dataclass(frozen=True)
class Dependency:
    """A parameter the data do not determine: its column is (numerically or nearly) a combination
    of the columns of others, or its estimate is dominated by noise."""

    name: str
    combination_of: tuple[str, ...]
    relative_residual: float
    inflation: float = math.nan
    relative_std: float = math.nan
    #: what ``relative_std`` is relative to (a centre-of-mass offset: the platform's size)
    scale: str = "its value"

    def describe(self) -> str:
        if math.isfinite(self.relative_std):
            how = (f"its standard deviation is {100 * self.relative_std:.0f} % of {self.scale}: the data hardly "
                   "excite it")
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
        if "B_w" in names:
            advice = "record the experiments named above, or fix B_w from a single-axis test (--fix B_w=VALUE)"
        elif any(n.startswith("offset_") for n in names):
            advice = "record the experiments named above, or do not estimate motor-torque offsets (--no-offsets)"
        else:
            advice = "record the experiments named above"
        super().__init__(f"{context}parameters {names} cannot be identified from these data:\n  {lines}\n{advice}")


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
    R = triangular_factor(A / column_norms(A))
    R_inv = solve_upper_triangular(R, np.eye(R.shape[0]))
    return np.einsum("ij,ij->i", R_inv, R_inv)
