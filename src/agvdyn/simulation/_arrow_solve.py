"""The plant's linear solve (numba): K x = rhs for the arrow-shaped iteration matrix of
:func:`agvdyn.simulation._plant_kernels.plant_step` (wheels couple only to the chassis and their
steering side, each steering side only to the chassis)."""
from __future__ import annotations

from agvdyn._jit import njit

_jit_borrow = njit(cache=True, error_model="numpy", _nrt=False)


@njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def _into_chassis(K, rhs, k0, k1, k2, f0, f1, f2, y):  # pragma: no cover - compiled
    """Eliminate one joint coupled to the chassis by ``(k0, k1, k2)`` (``f = k / pivot``, ``y`` its
    right-hand side) from the chassis block of K's lower triangle and from rhs."""
    K[0, 0] -= f0 * k0
    K[1, 0] -= f1 * k0
    K[1, 1] -= f1 * k1
    K[2, 0] -= f2 * k0
    K[2, 1] -= f2 * k1
    K[2, 2] -= f2 * k2
    rhs[0] -= f0 * y
    rhs[1] -= f1 * y
    rhs[2] -= f2 * y


@_jit_borrow
def _arrow_solve(K, rhs):
    """Solve K x = rhs in place for the plant's K (lower triangle read and overwritten); x in rhs.

    K is an arrow: each wheel (5-8) couples only to the chassis (0-2) and its steering side (3, 4),
    each steering side only to the chassis. Eliminating the wheels, then the steering sides, then
    the chassis block (LDL^T) makes no fill-in: about a third of the operations of a dense 9 x 9
    Cholesky and a much shorter chain of dependent ones (K is symmetric positive definite: no pivoting).
    """
    for i in range(4):
        p, a = 5 + i, 3 if i < 2 else 4
        k0, k1, k2, ka = K[p, 0], K[p, 1], K[p, 2], K[p, a]
        inv = 1.0 / K[p, p]
        f0, f1, f2, fa = k0 * inv, k1 * inv, k2 * inv, ka * inv
        y = rhs[p]
        _into_chassis(K, rhs, k0, k1, k2, f0, f1, f2, y)
        K[a, 0] -= fa * k0
        K[a, 1] -= fa * k1
        K[a, 2] -= fa * k2
        K[a, a] -= fa * ka
        rhs[a] -= fa * y
    for a in range(3, 5):
        k0, k1, k2 = K[a, 0], K[a, 1], K[a, 2]
        inv = 1.0 / K[a, a]
        _into_chassis(K, rhs, k0, k1, k2, k0 * inv, k1 * inv, k2 * inv, rhs[a])
    # chassis block: LDL^T, forward and back substitution
    d0 = K[0, 0]
    l10, l20 = K[1, 0] / d0, K[2, 0] / d0
    d1 = K[1, 1] - l10 * K[1, 0]
    k21 = K[2, 1] - l20 * K[1, 0]
    l21 = k21 / d1
    d2 = K[2, 2] - l20 * K[2, 0] - l21 * k21
    y1 = rhs[1] - l10 * rhs[0]
    y2 = rhs[2] - l20 * rhs[0] - l21 * y1
    x2 = y2 / d2
    x1 = y1 / d1 - l21 * x2
    x0 = rhs[0] / d0 - l10 * x1 - l20 * x2
    rhs[0], rhs[1], rhs[2] = x0, x1, x2
    for a in range(3, 5):
        rhs[a] = (rhs[a] - K[a, 0] * x0 - K[a, 1] * x1 - K[a, 2] * x2) / K[a, a]
    for i in range(4):
        p, a = 5 + i, 3 if i < 2 else 4
        rhs[p] = (rhs[p] - K[p, 0] * x0 - K[p, 1] * x1 - K[p, 2] * x2 - K[p, a] * rhs[a]) / K[p, p]
