"""Which parameters the data determine, and standard deviations that are infinite where they do not.

A covariance becomes a std in several places (the identification's uncertainty methods, the
planner's predictions, pre-flight trial fits, Monte Carlo studies). Each goes through here:

* :func:`determinacy`: rank test of an information matrix ``F = A^T W A``. It is scaled to unit
  diagonal (the W of eq. 25), and an eigenvalue at most ``tolerance`` times the largest spans an
  undetermined direction. Every parameter with a component in those directions (squared share
  above ``tolerance``) is undetermined, and so is a parameter whose column is zero. The test is
  the same on every machine: an exactly singular F has relative eigenvalues of ~1e-16, the
  hardly determined ones we know 1e-10 to 1e-6.
* :func:`sandwich_covariance`: ``F^+ Omega F^+`` (or ``F^+``) with the pseudo-inverse on the
  determined directions only. No ``inv`` of a matrix that may be singular.
* :func:`std_from_covariance`: ``sqrt(diag)``, ``inf`` for undetermined parameters. A negative or
  non-finite variance is never clipped to zero: it becomes ``inf`` with a warning naming the
  parameter.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["DETERMINACY_TOLERANCE", "Determinacy", "determinacy", "sandwich_covariance", "std_from_covariance",
           "std_from_information"]

#: Relative eigenvalue of the unit-diagonal information matrix at or below which a direction is
#: undetermined: a unit column within ~1e-6 of the span of the others, the identification's QR
#: rank test (``IdentificationSettings.rank_tolerance``) squared. An exactly singular system gives
#: ~1e-16 (B_w free on the default sequence, 40,000 rows); determined but hard cases: 1.6e-10 (all
#: eleven from a lane change alone, variance inflation 3e9, refused by the collinearity check with
#: its predicted std), 7e-7 (B_w from the default sequence plus a lane change, relative std ~6).
DETERMINACY_TOLERANCE = 1e-12


@dataclass(frozen=True, eq=False)
class Determinacy:
    """Rank test of an information matrix (:func:`determinacy`).

    ``scale`` (p,) the square roots of its diagonal; ``eigenvalues`` (p,) ascending and
    ``vectors`` (p, p) of the unit-diagonal matrix (zero columns left out: eigenvalue 0);
    ``undetermined`` (p,) bool; ``tolerance`` the relative eigenvalue of the test.
    """

    scale: np.ndarray
    eigenvalues: np.ndarray
    vectors: np.ndarray
    undetermined: np.ndarray
    tolerance: float

    @property
    def determined_directions(self) -> np.ndarray:
        """Mask of the eigen-directions above the tolerance."""
        top = float(self.eigenvalues[-1]) if self.eigenvalues.size else 0.0
        return self.eigenvalues > self.tolerance * top

    def names(self, names: Sequence[str]) -> tuple[str, ...]:
        """The undetermined parameters among ``names`` (in the matrix's order)."""
        return tuple(n for n, u in zip(names, self.undetermined) if u)


def determinacy(information: np.ndarray, *, tolerance: float = DETERMINACY_TOLERANCE) -> Determinacy:
    """Rank test of the symmetric information matrix ``F`` (p, p) with ``tolerance`` (module doc)."""
    F = np.asarray(information, dtype=float)
    if F.ndim != 2 or F.shape[0] != F.shape[1]:
        raise ValueError(f"information matrix of shape {F.shape}: expected a square matrix")
    if not np.all(np.isfinite(F)):
        bad = sorted({int(i) for i in np.argwhere(~np.isfinite(F))[:, 0]})
        raise ValueError(f"information matrix has non-finite entries in rows {bad}: expected finite numbers")
    if not 0 < tolerance < 1:
        raise ValueError(f"tolerance={tolerance!r}: expected a number in (0, 1)")
    diag = np.diag(F).copy()
    zero = ~(diag > 0)
    scale = np.sqrt(np.where(zero, 0.0, diag))
    s = np.where(zero, 1.0, scale)
    Fs = F / np.outer(s, s)
    Fs[zero, :] = 0.0
    Fs[:, zero] = 0.0
    lam, V = np.linalg.eigh(0.5 * (Fs + Fs.T))
    top = float(lam[-1]) if lam.size else 0.0
    null = lam <= tolerance * top if top > 0 else np.ones(lam.size, dtype=bool)
    share = np.einsum("ij,ij->i", V[:, null], V[:, null])
    return Determinacy(scale, lam, V, zero | (share > tolerance), float(tolerance))


def sandwich_covariance(information: np.ndarray, meat: np.ndarray | None = None, *,
                        tolerance: float = DETERMINACY_TOLERANCE) -> tuple[np.ndarray, Determinacy]:
    """Covariance ``F^+ Omega F^+`` (``meat`` Omega; None: ``F^+``) on the determined directions and
    the rank test. Rows and columns of undetermined parameters are 0 with ``inf`` on the diagonal."""
    det = determinacy(information, tolerance=tolerance)
    keep = det.determined_directions
    s = np.where(det.scale > 0, det.scale, 1.0)
    V = det.vectors[:, keep] / s[:, None]  # D^-1 V: F^+ = V diag(1/lam) V^T
    Fp = (V / det.eigenvalues[keep]) @ V.T
    cov = Fp if meat is None else Fp @ np.asarray(meat, dtype=float) @ Fp
    cov = 0.5 * (cov + cov.T)
    u = det.undetermined
    cov[u, :] = 0.0
    cov[:, u] = 0.0
    cov[u, u] = math.inf
    return cov, det


def std_from_covariance(cov: np.ndarray, names: Sequence[str] | None = None,
                        undetermined: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
    """``sqrt(diag(cov))`` with ``inf`` for the ``undetermined`` parameters and, with a warning
    naming the parameter, for a negative or non-finite variance (never clipped to zero)."""
    var = np.array(np.diag(np.asarray(cov, dtype=float)), dtype=float)
    names = list(names) if names is not None else [f"parameter {i}" for i in range(var.size)]
    std = np.full(var.size, math.inf)
    skip = np.zeros(var.size, dtype=bool) if undetermined is None else np.asarray(undetermined, dtype=bool)
    warnings = []
    for i, v in enumerate(var):
        if skip[i] or v == math.inf:
            continue
        if not (math.isfinite(v) and v >= 0):
            warnings.append(f"{names[i]}: variance {v:.3g} (negative or not finite, numerically undetermined): "
                            "its std is reported as inf")
            continue
        std[i] = math.sqrt(v)
    return std, warnings


def std_from_information(information: np.ndarray, meat: np.ndarray | None = None, *,
                         names: Sequence[str] | None = None, tolerance: float = DETERMINACY_TOLERANCE
                         ) -> tuple[np.ndarray, np.ndarray, Determinacy, list[str]]:
    """Std (inf where undetermined), covariance and rank test of ``F^+ Omega F^+``
    (:func:`sandwich_covariance`), with the warnings of :func:`std_from_covariance`."""
    cov, det = sandwich_covariance(information, meat, tolerance=tolerance)
    std, warnings = std_from_covariance(cov, names, det.undetermined)
    return std, cov, det, warnings
