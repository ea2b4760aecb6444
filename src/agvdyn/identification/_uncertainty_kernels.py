"""Compiled kernels of the delete-one-block jackknife (:mod:`.uncertainty`), without the GIL so that
recordings run in threads:

* :func:`step_scores`: the scores ``a_i w_i r_i`` summed per time step (correlation time, HAC);
* :func:`block_moments`: each block's weighted Gram ``A_b^T W A_b`` and score sum, row by row;
* :func:`block_changes`: for every block, its leverage matrix ``B^1/2 G_b B^1/2``, its trace and,
  where the trace bounds every leverage by 0.5, the solution of ``(I - M_b) x = B^1/2 S_b`` by
  Cholesky (the batched numpy formulation made one small LAPACK call per block).
"""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit

__all__ = ["block_moments", "block_changes", "step_scores"]


@njit(cache=True, nogil=True)
def block_moments(block, A, w, y, first, out, count, coef=None):  # pragma: no cover - compiled
    """Add ``w_i a_i^T [a_i | y_i]`` of every row i of ``A`` (m, p; a view of any strides) to
    ``out[block[i] - first]`` (nb, p, p + 1) and count the rows of each block in ``count`` (nb,);
    zero entries of a row are skipped (a coordinate's rows use a few of the columns). With
    ``coef`` (p,), the residual ``y_i - a_i coef`` takes the place of ``y_i`` (the score sums),
    formed from the row already read (no pass of its own, no copy of a strided A)."""
    m, p = A.shape
    row = np.empty(p + 1)
    for i in range(m):
        j = block[i] - first
        count[j] += 1
        for b in range(p):
            row[b] = A[i, b]
        if coef is None:
            row[p] = y[i]
        else:
            fit = 0.0
            for b in range(p):
                fit += row[b] * coef[b]
            row[p] = y[i] - fit
        for a in range(p):
            wa = w[i] * row[a]
            if wa == 0.0:
                continue
            for b in range(p + 1):
                out[j, a, b] += wa * row[b]


@njit(cache=True, nogil=True)
def block_changes(half, G, S, limit, M, x, trace):  # pragma: no cover - compiled
    """For blocks with Grams ``G`` (nb, p, p) and score sums ``S`` (nb, p) and ``half`` = B^1/2:
    ``M[b] = half G_b half`` (symmetrised), ``trace[b]`` its trace and ``x[b] = half S_b``; where
    ``trace[b] <= limit`` (every leverage at most ``limit`` < 1), ``x[b]`` is replaced by the
    solution of ``(I - M_b) x = half S_b``. Returns whether any block's trace exceeds ``limit``."""
    nb, p = S.shape
    T = np.empty((p, p))
    L = np.empty((p, p))
    any_high = False
    for k in range(nb):
        for i in range(p):  # T = G_b half
            for j in range(p):
                T[i, j] = 0.0
            for m in range(p):
                g = G[k, i, m]
                if g != 0.0:
                    for j in range(p):
                        T[i, j] += g * half[m, j]
        tr = 0.0
        for i in range(p):  # M = half T, upper triangle, mirrored
            for j in range(i, p):
                v = 0.0
                for m in range(p):
                    v += half[i, m] * T[m, j]
                M[k, i, j] = v
            tr += M[k, i, i]
        for i in range(p):
            for j in range(i):
                M[k, i, j] = M[k, j, i]
        trace[k] = tr
        for i in range(p):
            v = 0.0
            for m in range(p):
                v += half[i, m] * S[k, m]
            x[k, i] = v
        if tr > limit:
            any_high = True
            continue
        for j in range(p):  # Cholesky of I - M (eigenvalues in [1 - limit, 1])
            v = 1.0 - M[k, j, j]
            for m in range(j):
                v -= L[j, m] * L[j, m]
            d = np.sqrt(v)
            L[j, j] = d
            for i in range(j + 1, p):
                u = -M[k, i, j]
                for m in range(j):
                    u -= L[i, m] * L[j, m]
                L[i, j] = u / d
        for i in range(p):  # forward, then backward substitution
            v = x[k, i]
            for m in range(i):
                v -= L[i, m] * x[k, m]
            x[k, i] = v / L[i, i]
        for i in range(p - 1, -1, -1):
            v = x[k, i]
            for m in range(i + 1, p):
                v -= L[m, i] * x[k, m]
            x[k, i] = v / L[i, i]
    return any_high


@njit(cache=True, nogil=True)
def step_scores(A, y, w, coef, idx, out):  # pragma: no cover - compiled
    """Add the score ``a_i w_i (y_i - a_i coef)`` of every row i of ``A`` (m, p; any strides) to
    ``out[idx[i]]`` (T, p); rows with ``idx[i] >= T`` are left out."""
    m, p = A.shape
    T = out.shape[0]
    for i in range(m):
        t = idx[i]
        if t >= T:
            continue
        r = y[i]
        for c in range(p):
            r -= A[i, c] * coef[c]
        r *= w[i]
        for c in range(p):
            out[t, c] += A[i, c] * r
