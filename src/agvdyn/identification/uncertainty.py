"""Uncertainty of the estimates: classic (eq. 25), HAC (Newey-West, Bartlett) and moving-block
bootstrap, for residuals that are correlated in time within a continuous recording.

The zero-phase filtering and model error make the residuals of neighbouring samples strongly
correlated (integrated correlation times of tens to hundreds of samples), and different
generalized coordinates have residual levels that differ by 30x; eq. (25)'s one sigma for iid
rows is wrong both ways. Both corrections work on the scores ``g_i = a_i w_i r_i`` summed per
time step of each recording (rows of one sample are one observation):

* ``hac``: ``cov = B Omega B`` with ``B = (A^T W A)^-1`` and the Bartlett-kernel long-run
  covariance ``Omega = sum_t sum_s (1 - |t - s| / (L + 1)) g_t g_s^T`` within each recording,
  computed exactly as ``sum_windows S_w S_w^T / (L + 1)`` over all windows of L + 1 steps
  (partial at the ends), O(T p^2).
* ``bootstrap``: blocks of L steps of each recording resampled with replacement, the weighted
  normal equations re-solved per replicate (batched), covariance of the replicates.

The bandwidth L comes from the data: ``bandwidth_factor`` times the largest integrated
autocorrelation time of the score components (Sokal's window), at least ``min_bandwidth``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
import scipy.fft

from agvdyn.identification.estimators import Estimator

__all__ = ["UncertaintyMethod", "Uncertainty", "RowIndex", "parameter_uncertainty", "correlation_time"]


class UncertaintyMethod(str, Enum):
    """``identify --uncertainty``."""

    CLASSIC = "classic"
    HAC = "hac"
    BOOTSTRAP = "bootstrap"


@dataclass(frozen=True, eq=False)
class RowIndex:
    """Where each stacked row comes from: generalized coordinate ``group`` (codes into
    ``group_names``), ``recording`` (codes) and time ``step`` (sample index in the recording)."""

    group: np.ndarray
    group_names: tuple[str, ...]
    recording: np.ndarray
    step: np.ndarray


@dataclass(frozen=True, eq=False)
class Uncertainty:
    """Covariance of the free parameters by ``method``; ``details`` (bandwidth, replicates, ...)."""

    method: UncertaintyMethod
    cov: np.ndarray
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))


def _step_scores(scores: np.ndarray, rows: RowIndex) -> list[np.ndarray]:
    """Scores summed per time step, one dense (T_rec, p) array per recording (missing steps zero)."""
    out = []
    for rec in np.unique(rows.recording):
        sel = rows.recording == rec
        step = rows.step[sel]
        lo = int(step.min())
        idx = step - lo
        dense = np.zeros((int(idx.max()) + 1, scores.shape[1]))
        _add_rows(dense, idx, scores[sel])
        out.append(dense)
    return out


def _add_rows(dense: np.ndarray, idx: np.ndarray, values: np.ndarray) -> None:
    for j in range(values.shape[1]):
        dense[:, j] += np.bincount(idx, weights=values[:, j], minlength=dense.shape[0])


def correlation_time(series: list[np.ndarray], *, window: float = 5.0, max_steps: int = 1 << 17) -> np.ndarray:
    """Integrated autocorrelation time (in steps) of each column, pooled over the recordings:
    ``1 + 2 sum_{l=1}^{M} rho(l)`` with Sokal's window (the smallest M >= window * tau(M)).

    Each recording contributes at most its first ``max_steps`` steps (the correlation times are
    tens to hundreds of steps): the cost does not grow with the length of the log.
    """
    p = series[0].shape[1]
    acf = None
    for x in series:
        x = x[:max_steps]
        n = x.shape[0]
        size = scipy.fft.next_fast_len(2 * n, real=True)
        f = scipy.fft.rfft(x, size, axis=0, workers=-1)
        c = scipy.fft.irfft(f * np.conj(f), size, axis=0, workers=-1)[:n]
        acf = c if acf is None else _pad_add(acf, c)
    rho = acf / np.where(acf[0] > 0, acf[0], 1.0)
    tau = np.ones(p)
    for j in range(p):
        cum = 1 + 2 * np.cumsum(rho[1:, j])
        m = np.arange(1, cum.size + 1)
        ok = np.flatnonzero(m >= window * cum)
        tau[j] = max(1.0, float(cum[ok[0]] if ok.size else cum[-1]))
    return tau


def _pad_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if a.shape[0] < b.shape[0]:
        a, b = b, a
    a = a.copy()
    a[: b.shape[0]] += b
    return a


def _bartlett_meat(series: list[np.ndarray], L: int) -> np.ndarray:
    p = series[0].shape[1]
    omega = np.zeros((p, p))
    for g in series:
        T = g.shape[0]
        c = np.concatenate([np.zeros((1, p)), np.cumsum(g, axis=0)])
        starts = np.arange(-L, T)
        S = c[np.minimum(starts + L + 1, T)] - c[np.maximum(starts, 0)]
        omega += S.T @ S / (L + 1)
    return omega


def _bootstrap(A: np.ndarray, y: np.ndarray, w: np.ndarray, rows: RowIndex, L: int, replicates: int,
               seed: int) -> np.ndarray:
    """Covariance of the weighted LS solution over block-bootstrap replicates."""
    p = A.shape[1]
    Aw = A * w[:, None]
    grams, rhs, rec_of = [], [], []
    for k, rec in enumerate(np.unique(rows.recording)):
        sel = rows.recording == rec
        block = (rows.step[sel] - rows.step[sel].min()) // L
        nb = int(block.max()) + 1
        G = np.zeros((nb, p, p))
        b = np.zeros((nb, p))
        order = np.argsort(block, kind="stable")
        bounds = np.searchsorted(block[order], np.arange(nb + 1))
        As, Aws, ys = A[sel][order], Aw[sel][order], y[sel][order]
        for j in range(nb):
            a, e = bounds[j], bounds[j + 1]
            G[j] = Aws[a:e].T @ As[a:e]
            b[j] = Aws[a:e].T @ ys[a:e]
        grams.append(G)
        rhs.append(b)
        rec_of.append(nb)
    rng = np.random.default_rng(seed)
    coefs = np.empty((replicates, p))
    scale = np.sqrt(np.abs(np.diagonal(sum(G.sum(axis=0) for G in grams))))
    scale = np.where(scale > 0, scale, 1.0)
    for r in range(replicates):
        M = np.zeros((p, p))
        v = np.zeros(p)
        for G, b, nb in zip(grams, rhs, rec_of):
            counts = np.bincount(rng.integers(0, nb, nb), minlength=nb).astype(float)
            M += np.tensordot(counts, G, axes=1)
            v += counts @ b
        coefs[r] = np.linalg.solve(M / np.outer(scale, scale), v / scale) / scale
    return np.cov(coefs, rowvar=False)


def parameter_uncertainty(method: UncertaintyMethod | str, est: Estimator, A: np.ndarray, y: np.ndarray,
                          rows: RowIndex, *, bandwidth: int | None = None, bandwidth_factor: float = 2.0,
                          min_bandwidth: int = 50, replicates: int = 200, seed: int = 0) -> Uncertainty:
    """Covariance of ``est``'s free parameters by ``method`` (see the module docstring)."""
    method = UncertaintyMethod(method)
    if method is UncertaintyMethod.CLASSIC:
        return Uncertainty(method, est.cov_, {"sigma2": float(est.sigma2_)})
    w = est.weights_
    scores = A * (w * est.residual_)[:, None]
    series = _step_scores(scores, rows)
    tau = correlation_time(series)
    longest = max(s.shape[0] for s in series)
    L = int(bandwidth) if bandwidth is not None else int(min(max(min_bandwidth, math.ceil(bandwidth_factor * tau.max())),
                                                              max(1, longest // 4)))
    details: dict[str, Any] = {"bandwidth_steps": L, "correlation_time_steps": float(tau.max()),
                               "recordings": len(series)}
    if method is UncertaintyMethod.HAC:
        omega = _bartlett_meat(series, L)
        cov = est.bread_ @ omega @ est.bread_
    else:
        cov = _bootstrap(A, y, w, rows, L, replicates, seed)
        details.update(replicates=replicates, block_steps=L, seed=seed)
    active = getattr(est, "active_", ())
    if active:  # parameters held by a bound: no spread from the data
        fixed = np.all(est.bread_ == 0, axis=1)
        cov[fixed, :] = 0.0
        cov[:, fixed] = 0.0
    return Uncertainty(method, cov, details)
