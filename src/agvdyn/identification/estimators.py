"""Estimators of eq. (24) behind one interface (scikit-learn style): ``fit(A, y, groups=, names=)``
returns self with ``coef_``, ``cov_`` (the classic covariance), ``weights_`` (per row),
``residual_``, ``bread_`` (``(A^T W A)^-1``, for the sandwich covariances of
:mod:`agvdyn.identification.uncertainty`) and ``condition_number_``.

* ``ols``: the paper's column-scaled least squares, eq. (25), one residual variance for all rows.
* ``wls``: weights per generalized coordinate from its residual variance, iterated.
* ``robust``: IRLS with Huber or Tukey weights on the residual scaled by each coordinate's MAD;
  rows it down-weights are reported (``downweighted_``).
* ``bounded``: physically consistent (masses, inertias > 0, frictions >= 0, optional user bounds)
  by ``scipy.optimize.lsq_linear`` on the weighted, column-scaled problem; ``active_`` names the
  parameters at a bound.

All work on unit-norm columns (the W of eq. 25), solved by a QR of the weighted system.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np

from agvdyn.determinacy import std_from_covariance
from agvdyn.identifiability import triangular_factor

__all__ = ["Estimator", "LeastSquares", "WeightedLeastSquares", "Robust", "Bounded", "ESTIMATORS", "make_estimator",
           "column_norms", "condition_numbers", "solve_upper_triangular", "scaled_condition", "PHYSICAL_BOUNDS"]

#: Lower bounds of the physically consistent estimate (masses and inertias > 0, frictions >= 0).
PHYSICAL_BOUNDS: Mapping[str, tuple[float, float]] = {
    **dict.fromkeys(("C_l", "C_r", "m_ch", "C_ch", "B_w"), (1e-9, math.inf)),
    **dict.fromkeys(("d_vl", "d_cl", "d_vr", "d_cr", "d_vw", "d_cw"), (0.0, math.inf)),
    **dict.fromkeys(("d_sl", "d_sr", "d_sw"), (0.0, math.inf)),  # breakaway levels (agvdyn.model_spec)
}
#: MAD to standard deviation of normal data.
_MAD = 1.4826


def column_norms(A: np.ndarray) -> np.ndarray:
    """Euclidean norms of the columns of A (the diagonal of W^-1 in eq. 25)."""
    return np.sqrt(np.einsum("ij,ij->j", A, A))


def _weighted_fit(A: np.ndarray, y: np.ndarray, w: np.ndarray | None):
    """Column-scaled weighted least squares by QR: (coef, bread = (A^T W A)^-1, cond of the scaled
    normal matrix, unscaled cond)."""
    m, n = A.shape
    if m <= n:
        raise ValueError(f"least squares with {m} rows for {n} parameters: expected more rows than parameters")
    sw = None if w is None else np.sqrt(w)
    Aw = A if sw is None else A * sw[:, None]
    yw = y if sw is None else y * sw
    norms = column_norms(Aw)
    if np.any(norms == 0):
        raise ValueError(f"columns {np.flatnonzero(norms == 0).tolist()} of the regressor are zero")
    R_aug = triangular_factor(np.column_stack([Aw / norms, yw]))
    R, qty = R_aug[:n, :n], R_aug[:n, n]
    solved = solve_upper_triangular(R, np.column_stack([qty, np.eye(n)]))
    coef, R_inv = solved[:, 0] / norms, solved[:, 1:]
    bread = (R_inv @ R_inv.T) / np.outer(norms, norms)
    return (coef, bread, *condition_numbers(R, norms))


def solve_upper_triangular(R: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``R^-1 rhs`` of an upper triangular ``R`` (n, n) (the factor of eq. 25's QR), ``rhs`` (n,) or (n, k).

    numpy's LU solve (LAPACK dgesv): on a triangular matrix its factors are I and R exactly (no row
    swaps: the entries under the diagonal are zeros), so this is the triangular solve, without
    scipy.linalg's import (~0.2 s of every fitting command's start-up). Its round-off differs from
    ``scipy.linalg.solve_triangular``'s by an ulp (the parameters by ~1e-16, the jackknife's stds, whose
    residuals cancel, by ~1e-10 relative). A zero on the diagonal raises ``numpy.linalg.LinAlgError``."""
    return np.linalg.solve(R, rhs)


def condition_numbers(R: np.ndarray, norms: np.ndarray) -> tuple[float, float]:
    """``cond(Theta_w^T Theta_w)`` of the column-scaled regressor (eq. 25) from its triangular factor
    ``R`` (unit-norm columns), and the unscaled one (the columns' norms ``norms`` put back)."""
    sv = np.linalg.svd(R, compute_uv=False)
    sv_raw = np.linalg.svd(R * norms, compute_uv=False)
    return float((sv[0] / sv[-1]) ** 2), float((sv_raw[0] / sv_raw[-1]) ** 2)


def scaled_condition(A: np.ndarray) -> tuple[float, float]:
    """:func:`condition_numbers` of the rows ``A`` (scaled to unit-norm columns, as the estimators do)."""
    norms = column_norms(A)
    return condition_numbers(triangular_factor(A / norms), norms)


def _group_codes(groups: np.ndarray | None, m: int) -> np.ndarray:
    return np.zeros(m, dtype=np.int64) if groups is None else np.asarray(groups, dtype=np.int64)


class Estimator(ABC):
    """Interface: settings in ``__init__`` (no logic), ``fit`` returns self, results end in ``_``.

    ``fit(A, y, groups=None, names=None)``: stacked regressor of the free parameters and the
    right-hand side of eq. (24); ``groups`` (m,) the generalized coordinate of each row (weights
    and scales are per group), ``names`` the parameters of the columns. Pseudo-rows with the
    normal equations of the stacked rows (:mod:`agvdyn.identification.normal`) are given with
    ``group_rows`` (stacked rows per group), ``n_rows`` (all stacked rows) and optionally
    ``group_rss(coef)`` (residual sum of squares per group over the stacked rows, exact where the
    pseudo-rows lose digits to cancellation); estimators that need every residual (``robust``)
    refuse them (``needs_rows``).
    """

    needs_rows: bool = False

    name: str = ""
    coef_: np.ndarray
    cov_: np.ndarray
    condition_number_: float

    @abstractmethod
    def fit(self, A: np.ndarray, y: np.ndarray, *, groups: np.ndarray | None = None,
            names: Sequence[str] | None = None, group_rows: np.ndarray | None = None,
            n_rows: int | None = None, group_rss=None) -> "Estimator":
        ...

    @property
    def std_(self) -> np.ndarray:
        self._check_fitted()
        return std_from_covariance(self.cov_)[0]

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise RuntimeError(f"{type(self).__name__} is not fitted: call fit(A, y) first")

    def _finish(self, A: np.ndarray, y: np.ndarray, coef: np.ndarray, bread: np.ndarray, w: np.ndarray,
                cond: float, cond_raw: float, n_rows: int | None = None) -> None:
        """Set the common results; classic covariance ``s^2 (A^T W A)^-1``, ``s^2 = r^T W r / (m - n)``."""
        m, n = A.shape
        m = m if n_rows is None else n_rows
        r = y - A @ coef
        s2 = float(r @ (w * r)) / (m - n)
        self.coef_, self.bread_, self.weights_, self.residual_ = coef, bread, w, r
        self.cov_ = s2 * bread
        self.sigma2_ = s2
        self.residual_norm_ = float(np.sqrt(r @ r))
        self.condition_number_, self.condition_number_unscaled_ = cond, cond_raw
        self.n_rows_ = m


class LeastSquares(Estimator):
    """``ols``: least squares with column scaling, eq. (25).

    ``Theta_1,w = Theta_1 W`` with ``W = diag(1 / ||theta_1,i||)`` (unit-norm columns; the extracted
    text says W "contains the norms", the reciprocal is the reading that improves the
    conditioning). Classic covariance ``sigma^2 W (Theta_1,w^T Theta_1,w)^-1 W`` with one
    ``sigma^2 = |r|^2 / (m - n)`` for all rows. ``condition_number_`` is
    ``cond(Theta_1,w^T Theta_1,w)`` (the paper's 11.56).
    """

    name = "ols"

    def fit(self, A, y, *, groups=None, names=None, group_rows=None, n_rows=None, group_rss=None) -> "LeastSquares":
        A, y = np.asarray(A, dtype=float), np.asarray(y, dtype=float)
        coef, bread, cond, raw = _weighted_fit(A, y, None)
        self._finish(A, y, coef, bread, np.ones(A.shape[0]), cond, raw, n_rows)
        return self


def _group_variance(r: np.ndarray, groups: np.ndarray, group_rows: np.ndarray | None = None) -> np.ndarray:
    """Residual variance of each group (mean square over its ``group_rows`` stacked rows)."""
    k = int(groups.max()) + 1 if groups.size else 1
    num = np.bincount(groups, weights=r * r, minlength=k)
    den = np.bincount(groups, minlength=k) if group_rows is None else np.asarray(group_rows, dtype=float)
    return np.where(den > 0, num / np.maximum(den, 1e-300), 1.0)


class WeightedLeastSquares(Estimator):
    """``wls``: rows weighted by the inverse residual variance of their generalized coordinate,
    iterated from OLS until the weights settle (``max_iter``, relative ``tol``)."""

    name = "wls"

    def __init__(self, max_iter: int = 10, tol: float = 1e-3) -> None:
        self.max_iter = max_iter
        self.tol = tol

    def fit(self, A, y, *, groups=None, names=None, group_rows=None, n_rows=None, group_rss=None
            ) -> "WeightedLeastSquares":
        A, y = np.asarray(A, dtype=float), np.asarray(y, dtype=float)
        g = _group_codes(groups, A.shape[0])

        def variance(coef):
            if group_rss is None:
                return _group_variance(y - A @ coef, g, group_rows)
            return np.asarray(group_rss(coef)) / np.maximum(np.asarray(group_rows, dtype=float), 1.0)

        coef, *_ = _weighted_fit(A, y, None)
        var = variance(coef)
        for self.n_iter_ in range(1, self.max_iter + 1):
            w = 1.0 / np.maximum(var[g], 1e-300)
            coef, bread, cond, raw = _weighted_fit(A, y, w)
            new = variance(coef)
            done = np.max(np.abs(new / var - 1)) < self.tol
            var = new
            if done:
                break
        self.group_variance_ = var
        self._finish(A, y, coef, bread, w, cond, raw, n_rows)
        return self


class Robust(Estimator):
    """``robust``: iteratively reweighted least squares, Huber (``c = 1.345``) or Tukey biweight
    (``c = 4.685``) on residuals scaled per generalized coordinate by ``1.4826 MAD``; combined with
    the coordinate's inverse variance. ``downweighted_`` (m,) marks rows with weight below half."""

    name = "robust"
    needs_rows = True

    def __init__(self, loss: Literal["huber", "tukey"] = "tukey", c: float | None = None, max_iter: int = 30,
                 tol: float = 1e-6) -> None:
        self.loss = loss
        self.c = c
        self.max_iter = max_iter
        self.tol = tol

    def _psi_weight(self, u: np.ndarray) -> np.ndarray:
        if self.loss == "huber":
            c = 1.345 if self.c is None else self.c
            a = np.abs(u)
            return np.where(a <= c, 1.0, c / np.maximum(a, 1e-300))
        if self.loss == "tukey":
            c = 4.685 if self.c is None else self.c
            return np.where(np.abs(u) < c, (1 - (u / c) ** 2) ** 2, 0.0)
        raise ValueError(f"robust loss {self.loss!r}: expected 'huber' or 'tukey'")

    def fit(self, A, y, *, groups=None, names=None, group_rows=None, n_rows=None, group_rss=None) -> "Robust":
        if group_rows is not None:
            raise ValueError("the robust estimator weighs every row: give it the stacked rows, not pseudo-rows")
        A, y = np.asarray(A, dtype=float), np.asarray(y, dtype=float)
        g = _group_codes(groups, A.shape[0])
        k = int(g.max()) + 1
        coef, *_ = _weighted_fit(A, y, None)
        for self.n_iter_ in range(1, self.max_iter + 1):
            r = y - A @ coef
            scale = np.ones(k)
            for j in range(k):
                rj = r[g == j]
                if rj.size:
                    scale[j] = max(_MAD * float(np.median(np.abs(rj - np.median(rj)))), 1e-12)
            psi = self._psi_weight(r / scale[g])
            w = psi / scale[g] ** 2
            new, bread, cond, raw = _weighted_fit(A, y, w)
            step = np.max(np.abs(new - coef) / np.maximum(np.abs(new), 1e-12))
            coef = new
            if step < self.tol:
                break
        self.scale_ = scale
        self.downweighted_ = psi < 0.5
        self._finish(A, y, coef, bread, w, cond, raw)
        return self


class Bounded(Estimator):
    """``bounded``: physically consistent weighted least squares (weights as ``wls``), subject to
    :data:`PHYSICAL_BOUNDS` and the user's ``bounds`` ``{name: (low, high)}``; nuisance columns
    (motor-torque offsets) are free. ``active_`` lists the parameters at a bound; their covariance
    rows are zero (the bound, not the data, fixes them)."""

    name = "bounded"

    def __init__(self, bounds: Mapping[str, tuple[float, float]] | None = None) -> None:
        self.bounds = bounds

    def fit(self, A, y, *, groups=None, names=None, group_rows=None, n_rows=None, group_rss=None) -> "Bounded":
        A, y = np.asarray(A, dtype=float), np.asarray(y, dtype=float)
        names = list(names) if names is not None else [f"p{i}" for i in range(A.shape[1])]
        table = {**PHYSICAL_BOUNDS, **dict(self.bounds or {})}
        low = np.array([table.get(n, (-math.inf, math.inf))[0] for n in names], dtype=float)
        high = np.array([table.get(n, (-math.inf, math.inf))[1] for n in names], dtype=float)
        if np.any(low > high):
            bad = [n for n, a, b in zip(names, low, high) if a > b]
            raise ValueError(f"bounds of {bad}: lower bound above upper bound")
        wls = WeightedLeastSquares().fit(A, y, groups=groups, group_rows=group_rows, n_rows=n_rows, group_rss=group_rss)
        w = wls.weights_
        sw = np.sqrt(w)
        norms = column_norms(A * sw[:, None])
        R_aug = triangular_factor(np.column_stack([A * sw[:, None] / norms, y * sw]))
        n = A.shape[1]
        R, qty = R_aug[:n, :n], R_aug[:n, n]
        # min |R z - Q^T y| over the scaled unknowns z = norms * p: same minimiser as the full problem
        import scipy.optimize  # here only: ~0.1 s of start-up for the other estimators

        sol = scipy.optimize.lsq_linear(R, qty, bounds=(low * norms, high * norms), method="bvls", tol=1e-12)
        coef = sol.x / norms
        span = np.maximum(np.abs(coef), 1e-12)
        active = (np.abs(coef - low) <= 1e-9 * span + 1e-12) | (np.abs(coef - high) <= 1e-9 * span + 1e-12)
        free = ~active
        bread = np.zeros((n, n))
        if free.any():
            _, b_free, cond, raw = _weighted_fit(A[:, free], y - A[:, active] @ coef[active], w)
            bread[np.ix_(free, free)] = b_free
        else:
            cond = raw = math.nan
        self.active_ = tuple(nm for nm, a in zip(names, active) if a)
        self._finish(A, y, coef, bread, w, cond, raw, n_rows)
        return self


#: Estimators by the names of ``identify --estimator``.
ESTIMATORS = {"ols": LeastSquares, "wls": WeightedLeastSquares, "robust": Robust, "bounded": Bounded}


def make_estimator(name: str, **options) -> Estimator:
    """An estimator by name (:data:`ESTIMATORS`); ValueError listing the names otherwise."""
    try:
        cls = ESTIMATORS[name]
    except KeyError:
        raise ValueError(f"estimator {name!r}: expected one of {sorted(ESTIMATORS)}") from None
    return cls(**options)
