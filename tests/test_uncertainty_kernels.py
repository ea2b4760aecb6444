"""The jackknife's compiled kernels (agvdyn.identification._uncertainty_kernels) against the numpy
formulation they replace."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from agvdyn.identification._uncertainty_kernels import block_changes, block_moments, step_scores

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics


def _spd_blocks(rng, nb, p, scale):
    X = rng.standard_normal((nb, 3 * p, p))
    return scale * np.einsum("bki,bkj->bij", X, X) / (3 * p)


@hsettings(deadline=None, max_examples=25)
@given(st.integers(1, 12), st.integers(1, 40), st.integers(0, 2**32 - 1))
def test_block_changes_equal_the_batched_numpy_solution(p, nb, seed):
    rng = np.random.default_rng(seed)
    H = rng.standard_normal((p, p))
    half = H @ H.T / p + np.eye(p)  # a symmetric B^1/2
    G = _spd_blocks(rng, nb, p, rng.uniform(0.05, 1.2) / np.trace(half @ half))  # traces 0.05-1.2
    S = rng.standard_normal((nb, p))
    M, x, trace = np.empty((nb, p, p)), np.empty((nb, p)), np.empty(nb)
    high = block_changes(half, G, S, 0.5, M, x, trace)
    ref = half @ G @ half
    np.testing.assert_allclose(M, (ref + np.swapaxes(ref, 1, 2)) / 2, rtol=1e-12, atol=1e-14 * np.abs(ref).max())
    np.testing.assert_allclose(trace, np.einsum("bii->b", ref), rtol=1e-12)
    low = trace <= 0.5
    assert high == (not low.all())
    want = S @ half
    want[low] = np.linalg.solve(np.eye(p) - ref[low], want[low][..., None])[..., 0]
    np.testing.assert_allclose(x, want, rtol=1e-10, atol=1e-12 * np.abs(want).max())


def test_block_moments_are_the_weighted_grams_of_each_block():
    rng = np.random.default_rng(4)
    m, p = 500, 6
    A = rng.standard_normal((m, p))
    A[rng.random((m, p)) < 0.3] = 0.0  # zero entries are skipped
    w, y = rng.uniform(0.5, 2.0, m), rng.standard_normal(m)
    block = np.sort(rng.integers(3, 11, m))
    out, count = np.zeros((8, p, p + 1)), np.zeros(8, dtype=np.int64)
    block_moments(block, A[:, :p], w, y, 3, out, count)
    for j in range(8):
        sel = block == j + 3
        Ay = np.column_stack([A[sel], y[sel]])
        np.testing.assert_allclose(out[j], (A[sel] * w[sel, None]).T @ Ay, rtol=1e-12, atol=1e-12)
        assert count[j] == sel.sum()
    coef = rng.standard_normal(p)  # the residual y - A coef in place of y: the score sums
    wide = np.column_stack([A, rng.standard_normal(m)])  # A as a strided view of wider stored rows
    res, res_count = np.zeros((8, p, p + 1)), np.zeros(8, dtype=np.int64)
    block_moments(block, wide[:, :p], w, y, 3, res, res_count, coef)
    r = y - A @ coef
    for j in range(8):
        sel = block == j + 3
        np.testing.assert_allclose(res[j, :, :p], out[j, :, :p], rtol=0, atol=0)
        np.testing.assert_allclose(res[j, :, p], (A[sel] * w[sel, None]).T @ r[sel], rtol=1e-12, atol=1e-12)


def test_block_changes_leave_blocks_above_the_limit_unsolved():
    p = 3
    half = np.eye(p)
    G = np.stack([0.1 * np.eye(p), 0.4 * np.eye(p)])  # traces 0.3 and 1.2
    S = np.ones((2, p))
    M, x, trace = np.empty((2, p, p)), np.empty((2, p)), np.empty(2)
    assert block_changes(half, G, S, 0.5, M, x, trace)
    np.testing.assert_allclose(trace, [0.3, 1.2])
    np.testing.assert_allclose(x, [np.full(p, 1 / 0.9), np.ones(p)])  # (I - 0.1 I)^-1 1; the second as B^1/2 S


def test_step_scores_sum_each_steps_scores_and_leave_out_late_steps():
    rng = np.random.default_rng(5)
    m, p, T = 400, 5, 150
    A, y, w, coef = rng.standard_normal((m, p)), rng.standard_normal(m), rng.uniform(0.5, 2, m), rng.standard_normal(p)
    idx = rng.integers(0, 200, m)  # repeated steps, and steps beyond T
    out = np.zeros((T, p))
    step_scores(A, y, w, coef, idx, out)
    scores = A * (w * (y - A @ coef))[:, None]
    want = np.zeros((200, p))
    np.add.at(want, idx, scores)
    np.testing.assert_allclose(out, want[:T], rtol=1e-12, atol=1e-12)
