"""Stage 3: the stacked regression of eq. (22)-(25), the rank and quality checks, estimators."""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from agvdyn.dynamics import N_P
from agvdyn.identifiability import base_parameters_of, triangular_factor
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.settings import EXCITATION, OFFSET_NAMES

__all__ = ["stacked_system", "Dependency", "UnidentifiableError", "dependent_parameters", "variance_inflation",
           "column_norms", "Estimator", "LeastSquares"]

#: Order in which the rank check accepts columns: the representative the paper names for each
#: group of parameters that multiply the same signal comes first (Table 1: C_ch in rotation,
#: m_ch in straight motion), B_w last (the paper's dependent parameter p_2, sec. 6.3).
_RANK_ORDER = ("m_ch", "C_ch", "d_vw", "d_cw", "C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr", "B_w", *OFFSET_NAMES)


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
        if "B_w" in names:
            advice = "record the experiments named above, or fix B_w from a single-axis test (--fix B_w=VALUE)"
        elif any(n.startswith("offset_") for n in names):
            advice = "record the experiments named above, or do not estimate motor-torque offsets (--no-offsets)"
        else:
            advice = "record the experiments named above"
        super().__init__(f"{context}parameters {names} cannot be identified from these data:\n  {lines}\n{advice}")


def column_norms(A: np.ndarray) -> np.ndarray:
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
    R = triangular_factor(A / column_norms(A))
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
        norms = column_norms(A)
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


