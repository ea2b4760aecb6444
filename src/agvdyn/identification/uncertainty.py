"""Uncertainty of the estimates: classic (eq. 25), HAC (Newey-West, Bartlett), delete-one-block
jackknife and moving-block bootstrap, for residuals that are correlated in time within a
continuous recording.

The zero-phase filtering and model error make the residuals of neighbouring samples strongly
correlated (integrated correlation times of tens to hundreds of samples), and different
generalized coordinates have residual levels that differ by 30x; eq. (25)'s one sigma for iid
rows is wrong both ways. Both corrections work on the scores ``g_i = a_i w_i r_i`` summed per
time step of each recording (rows of one sample are one observation):

* ``hac``: ``cov = B Omega B`` with ``B = (A^T W A)^-1`` and the Bartlett-kernel long-run
  covariance ``Omega = sum_t sum_s (1 - |t - s| / (L + 1)) g_t g_s^T`` within each recording,
  computed exactly as ``sum_windows S_w S_w^T / (L + 1)`` over all windows of L + 1 steps
  (partial at the ends), O(T p^2).
* ``jackknife`` (the default): delete-one-block jackknife (CR3) over non-overlapping blocks of
  2 L steps of each recording, ``cov = sum_b d_b d_b^T`` with the exact change of the solution
  when block b is left out, ``d_b = B (I - G_b B)^-1 S_b`` (``G_b = A_b^T W A_b``, ``S_b`` the
  block's score sum). HAC's residuals are shrunk where a block has high leverage (the information
  of an identification sits in a few tens of effective blocks), which makes its std 5-10 % too
  small; the jackknife undoes the shrinkage. The largest block leverage (eigenvalue of
  ``G_b B``) is reported; above 0.5 a warning says the data hang on a few blocks. A variance
  summed from blocks of unequal weight is itself uncertain: each parameter's interval uses
  Student's t with Satterthwaite's degrees of freedom ``3 (sum_b c_b)^2 / sum_b c_b^2``
  (``c_b = d_b^2``; exact in expectation for independent normal block changes; on our simulator
  it overstates the scatter-implied degrees of freedom by about 1.3x, so the correction is partial).
* ``bootstrap``: blocks of L steps of each recording resampled with replacement, the weighted
  normal equations re-solved per replicate (batched), covariance of the replicates.

The bandwidth L comes from the data: ``bandwidth_factor`` times the largest integrated
autocorrelation time of the score components (Sokal's window), at least ``min_bandwidth``.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable, Iterable, Iterator, Sequence

import numpy as np

from agvdyn.determinacy import std_from_covariance
from agvdyn.identification._student_t import normal_quantile, student_t_quantile
from agvdyn.identification._uncertainty_kernels import block_changes, block_moments, step_scores
from agvdyn.identification._threads import ordered_map
from agvdyn.identification.correlation import correlation_time
from agvdyn.identification.estimators import Estimator
from agvdyn.identification.normal import RecordingRows, RegressionData, RowIndex
from agvdyn.identification.stage_settings import UncertaintyMethod

__all__ = ["UncertaintyMethod", "Uncertainty", "RowIndex", "parameter_uncertainty", "correlation_time"]


@dataclass(frozen=True, eq=False)
class Uncertainty:
    """Covariance of the free parameters by ``method``; ``details`` (bandwidth, replicates, ...);
    ``warnings`` on the data's fitness for the method."""

    method: UncertaintyMethod
    cov: np.ndarray
    details: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    dof: np.ndarray | None = None  # degrees of freedom of each variance (None: known, normal quantile)

    @property
    def std(self) -> np.ndarray:
        """``sqrt(diag(cov))``; ``inf`` where a variance is negative or not finite
        (:func:`agvdyn.determinacy.std_from_covariance`, whose warnings the fit reports)."""
        return std_from_covariance(self.cov)[0]

    def quantile(self, level: float = 0.95) -> np.ndarray:
        """Two-sided ``level`` quantile of each parameter's interval ``value +- q std``: Student's t
        with ``dof`` degrees of freedom (the variance is itself estimated from few blocks), else normal."""
        if self.dof is None:  # scipy.special's ndtri and stdtrit to ~1e-16 and 1e-12, without its import
            return np.full(self.cov.shape[0], normal_quantile(0.5 + level / 2))
        return student_t_quantile(np.maximum(self.dof, 1.0), 0.5 + level / 2)


def _recording_jobs(est: Estimator, data: RegressionData) -> Iterator[Callable[[], tuple[RecordingRows, np.ndarray]]]:
    """One callable per recording returning its rows (free columns, eq. 24) and the estimator's
    weight of each row; the rows are formed when it is called (in a worker thread)."""
    w = np.asarray(est.weights_, dtype=float)
    if data.row_order is not None:
        w = w[data.row_order]
    if data.pseudo:  # one weight per generalized coordinate
        per_group = np.ones(len(data.group_names))
        per_group[data.group] = w

    def weighed(job: Callable[[], RecordingRows], start: int | None) -> tuple[RecordingRows, np.ndarray]:
        rec = job()
        return rec, (per_group[rec.group] if start is None else w[start:start + rec.y.size])

    start = 0
    for job, rows in zip(data.recording_jobs(), data.store.row_counts()):
        yield functools.partial(weighed, job, None if data.pseudo else start)
        start += rows


def _recording_weights(est: Estimator, data: RegressionData) -> Iterator[tuple[RecordingRows, np.ndarray]]:
    """Each recording's rows (free columns, eq. 24) with the estimator's weight of each row."""
    for job in _recording_jobs(est, data):
        yield job()


def _step_scores(est: Estimator, data: RegressionData, max_steps: int | None = None) -> Iterator[np.ndarray]:
    """Scores ``a_i w_i r_i`` summed per time step, one dense (T_rec, p) array per recording (missing
    steps zero; only the first ``max_steps`` steps when given); one recording at a time."""
    for rec, w in _recording_weights(est, data):
        yield _dense_scores(rec, w, est.coef_, max_steps)


def _dense_scores(rec: RecordingRows, w: np.ndarray, coef: np.ndarray, max_steps: int | None) -> np.ndarray:
    """One recording's scores summed per time step (see :func:`_step_scores`), in one compiled pass."""
    idx = rec.step - int(rec.step.min())
    T = int(idx.max()) + 1 if max_steps is None else min(int(idx.max()) + 1, max_steps)
    dense = np.zeros((T, rec.A.shape[1]))
    step_scores(np.asarray(rec.A, dtype=float), np.ascontiguousarray(rec.y, dtype=float),
                np.ascontiguousarray(w, dtype=float), np.ascontiguousarray(coef, dtype=float),
                np.ascontiguousarray(idx, dtype=np.int64), dense)
    return dense


def _bartlett_meat(series: Iterable[np.ndarray], L: int, p: int) -> np.ndarray:
    omega = np.zeros((p, p))
    for g in series:
        T = g.shape[0]
        c = np.concatenate([np.zeros((1, p)), np.cumsum(g, axis=0)])
        starts = np.arange(-L, T)
        S = c[np.minimum(starts + L + 1, T)] - c[np.maximum(starts, 0)]
        omega += S.T @ S / (L + 1)
    return omega


def _block_moments(est: Estimator, data: RegressionData, L: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Per recording (the bootstrap's strata), the weighted Gram ``A_b^T W A_b`` (nb, p, p) and
    ``A_b^T W y_b`` (nb, p) of its non-overlapping blocks of L sample steps, counted from its first
    step, empty ones included."""
    p = data.A.shape[1]
    for rec, w in _recording_weights(est, data):
        ids, G, b = _block_sums((rec.step - rec.step.min()) // L, rec.A, w, rec.y)
        G_all, b_all = np.zeros((int(ids[-1]) + 1, p, p)), np.zeros((int(ids[-1]) + 1, p))
        G_all[ids], b_all[ids] = G, b
        yield G_all, b_all


def _block_sums(block: np.ndarray, A: np.ndarray, w: np.ndarray, y: np.ndarray, coef: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block ids present (sorted) and, per block, ``A_b^T W A_b`` (nb, p, p) and ``A_b^T W y_b``
    (nb, p) (``y - A coef`` in place of y with ``coef``: the score sums), summed row by row in one
    compiled pass without the GIL (recordings in threads; :func:`._uncertainty_kernels.block_moments`)."""
    p = A.shape[1]
    first = int(block.min())
    moments = np.zeros((int(block.max()) - first + 1, p, p + 1))
    count = np.zeros(moments.shape[0], dtype=np.int64)
    block_moments(np.ascontiguousarray(block, dtype=np.int64), np.asarray(A, dtype=float),  # A: a view, not copied
                  np.ascontiguousarray(w, dtype=float), np.ascontiguousarray(y, dtype=float), first, moments, count,
                  None if coef is None else np.ascontiguousarray(coef, dtype=float))
    present = np.flatnonzero(count)
    return present + first, moments[present, :, :p], moments[present, :, p]


def _bootstrap(est: Estimator, data: RegressionData, L: int, replicates: int, seed: int) -> np.ndarray:
    """Covariance of the weighted LS solution over block-bootstrap replicates."""
    p = data.A.shape[1]
    grams, rhs = zip(*_block_moments(est, data, L))
    rng = np.random.default_rng(seed)
    coefs = np.empty((replicates, p))
    scale = np.sqrt(np.abs(np.diagonal(sum(G.sum(axis=0) for G in grams))))
    scale = np.where(scale > 0, scale, 1.0)
    for r in range(replicates):
        M = np.zeros((p, p))
        v = np.zeros(p)
        for G, b in zip(grams, rhs):
            nb = b.shape[0]
            counts = np.bincount(rng.integers(0, nb, nb), minlength=nb).astype(float)
            M += np.tensordot(counts, G, axes=1)
            v += counts @ b
        coefs[r] = np.linalg.solve(M / np.outer(scale, scale), v / scale) / scale
    return np.cov(coefs, rowvar=False)


#: Degrees of freedom below which the jackknife warns (fewer than ~2 effective blocks); leverages
#: above LEVERAGE_WARNING are counted and capped at MAX_LEVERAGE (a block that alone determines a
#: direction cannot be left out).
MIN_DOF = 5.0
LEVERAGE_WARNING = 0.5
MAX_LEVERAGE = 0.95


def _largest_leverage(M: np.ndarray, trace: np.ndarray, top: float, among: np.ndarray, batch: int = 16) -> float:
    """max(top, largest eigenvalue of the blocks ``M[among]`` (of M (nb, p, p))), visiting them by
    decreasing trace (an upper bound of a positive semi-definite block's largest eigenvalue) while
    it can exceed top: only blocks whose trace is above ``top`` are looked at."""
    among = among[trace[among] > top]
    order = among[np.argsort(-trace[among])]
    for i in range(0, order.size, batch):
        ids = order[i:i + batch]
        ids = ids[trace[ids] > top]
        if not ids.size:
            break
        top = max(top, float(np.linalg.eigvalsh(M[ids])[:, -1].max()))
    return top


def _jackknife(est: Estimator, data: RegressionData, L: int, workers: int = 1
               ) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Delete-one-block jackknife (CR3) covariance over blocks of L steps, the degrees of freedom of
    each variance and the leverage figures.

    Blocks are cut at multiples of L of the log's sample index, and a block that a recording shares
    with the next one of the same log (stretches, and the pieces a long log is read in, follow each
    other with increasing steps) is summed over both: a long log read in pieces gets the whole
    log's blocks. Each recording is one job in ``workers`` threads: its score sums ``A_b^T W r_b``
    (no cancellation) and the changes of its inner blocks; its first and last block, which a
    neighbour may continue, are completed in order here and their changes taken at the end."""
    B = est.bread_
    lam, V = np.linalg.eigh((B + B.T) / 2)
    half = (V * np.sqrt(np.maximum(lam, 0.0))) @ V.T  # B^(1/2)
    p = B.shape[0]

    largest = [0.0]  # the largest block leverage found so far, in any thread: blocks whose trace
    # (a bound of their leverage) is below it need no eigenvalues (a stale read only costs time)

    def job(item: Callable[[], tuple[RecordingRows, np.ndarray]]):
        rec, w = item()
        ids, G, S = _block_sums(rec.step // L, rec.A, w, rec.y, est.coef_)
        inner = _block_changes(half, G[1:-1], S[1:-1], largest[0]) if ids.size > 2 else None
        if inner is not None:
            largest[0] = max(largest[0], inner[3])
        ends = [0, ids.size - 1] if ids.size > 1 else [0]
        return int(rec.step.min()), int(rec.step.max()), ids[ends], G[ends], S[ends], inner

    changes = []  # per chunk of blocks: sum d d^T, sum d^4, blocks, largest leverage, above 0.5, capped columns
    edges: list[tuple[np.ndarray, np.ndarray]] = []  # completed first and last blocks
    pending: tuple[int, np.ndarray, np.ndarray] | None = None  # per log: the last block, maybe continued
    last_step = None
    for first, last, ids, G, S, inner in ordered_map(job, _recording_jobs(est, data), workers, "agvdyn-jackknife"):
        if inner is not None:
            changes.append(inner)
        new_log = last_step is None or first <= last_step  # steps start again: another log
        last_step = last
        if pending is not None:
            if not new_log and ids[0] == pending[0]:  # the previous recording's last block goes on here
                G[0] += pending[1]
                S[0] += pending[2]
            else:
                edges.append(pending[1:])
        if ids.size > 1:
            edges.append((G[0], S[0]))
        pending = (int(ids[-1]), G[-1], S[-1])
    if pending is not None:
        edges.append(pending[1:])
    if edges:
        changes.append(_block_changes(half, np.stack([g for g, _ in edges]), np.stack([s for _, s in edges]),
                                      largest[0]))
    dd, d4, counts, tops, above, single = zip(*changes) if changes else ((),) * 6
    cov, c_sq = sum(dd, np.zeros((p, p))), sum(d4, np.zeros(p))
    blocks, top, capped = sum(counts), max(tops, default=0.0), set().union(*single)
    above = sum(above)
    dof = np.where(c_sq > 0, 3.0 * np.diag(cov) ** 2 / np.where(c_sq > 0, c_sq, 1.0), np.inf)  # Satterthwaite
    return cov, dof, {"blocks": blocks, "block_steps": L, "max_block_leverage": top,
                      "blocks_above_half_leverage": above, "single_block_columns": sorted(capped)}


def _block_changes(half: np.ndarray, G: np.ndarray, S: np.ndarray, known: float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray, int, float, int, set[int]]:
    """For blocks with Grams G (nb, p, p) and score sums S (nb, p): ``sum_b d_b d_b^T`` and
    ``sum_b d_b^4`` of the changes ``d_b = B (I - G_b B)^-1 S_b``, the number of blocks, their
    largest leverage, how many exceed LEVERAGE_WARNING and the columns of directions one block
    alone determines (leverage above MAX_LEVERAGE, capped there). ``known``: a leverage already found
    in other blocks; blocks whose trace is below it are not looked at for the largest (which is then
    at least ``known``)."""
    nb, p = S.shape
    # M_b = B^1/2 G_b B^1/2 (eigenvalues: block leverages), its trace (>= the largest leverage, M
    # is positive semi-definite) and x_b = B^1/2 S_b; where the trace allows no leverage above 0.5,
    # x_b solves (I - M_b) x = B^1/2 S_b (compiled, per block)
    M, x, trace = np.empty((nb, p, p)), np.empty((nb, p)), np.empty(nb)
    block_changes(np.ascontiguousarray(half), np.ascontiguousarray(G), np.ascontiguousarray(S), LEVERAGE_WARNING,
                  M, x, trace)
    low = trace <= LEVERAGE_WARNING
    top, above, capped = 0.0, 0, set()
    if low.any():
        top = _largest_leverage(M, trace, known, np.flatnonzero(low))
    high = np.flatnonzero(~low)
    if high.size:  # the leverages: capped at MAX_LEVERAGE, counted, the largest reported
        h, Q = np.linalg.eigh(M[high])
        top = max(top, float(h[:, -1].max()))
        above = int(np.count_nonzero(h[:, -1] > LEVERAGE_WARNING))
        for j in np.flatnonzero(h[:, -1] > MAX_LEVERAGE):  # directions one block alone determines
            v = np.abs(half @ Q[j, :, -1])
            capped.update(np.flatnonzero(v > 0.3 * v.max()).tolist())
        z = np.einsum("bji,bj->bi", Q, x[high]) / (1.0 - np.minimum(h, MAX_LEVERAGE))
        x[high] = np.einsum("bij,bj->bi", Q, z)
    d = x @ half  # B (I - G_b B)^-1 S_b
    return d.T @ d, (d**4).sum(axis=0), S.shape[0], top, above, capped


def parameter_uncertainty(method: UncertaintyMethod | str, est: Estimator, data: RegressionData, *,
                          bandwidth: int | None = None, bandwidth_factor: float = 2.0,
                          min_bandwidth: int = 50, replicates: int = 200, seed: int = 0,
                          names: Sequence[str] | None = None, reported: Iterable[str] = (), workers: int = 1
                          ) -> Uncertainty:
    """Covariance of ``est``'s free parameters by ``method`` (see the module docstring); the rows
    are read one recording at a time from ``data`` (twice: correlation time, then the meat). L is
    the HAC bandwidth and bootstrap block; the jackknife's blocks are 2 L long (the Bartlett window
    of L lags and non-overlapping blocks of 2 L steps cover the same correlations). ``names`` of
    the columns: the jackknife's warning names those in ``reported`` (default: all) whose
    variance has fewer than MIN_DOF degrees of freedom. ``workers``: threads of the jackknife's block sums."""
    reported = set(reported) or set(names or ())
    method = UncertaintyMethod(method)
    if method is UncertaintyMethod.CLASSIC:
        return Uncertainty(method, est.cov_, {"sigma2": float(est.sigma2_)})
    lengths = data.store.lengths()  # without reading the rows back
    scores = (functools.partial(lambda job: _dense_scores(*job(), est.coef_, 1 << 15), job)
              for job in _recording_jobs(est, data))  # formed in the threads
    tau = correlation_time(scores, workers=workers, lengths=lengths)
    L = int(bandwidth) if bandwidth is not None else int(min(max(min_bandwidth, math.ceil(bandwidth_factor * tau.max())),
                                                              max(1, max(lengths) // 4)))
    details: dict[str, Any] = {"bandwidth_steps": L, "correlation_time_steps": float(tau.max()),
                               "recordings": len(lengths)}
    warnings: tuple[str, ...] = ()
    dof = None
    if method is UncertaintyMethod.HAC:
        omega = _bartlett_meat(_step_scores(est, data), L, data.A.shape[1])
        cov = est.bread_ @ omega @ est.bread_
    elif method is UncertaintyMethod.JACKKNIFE:
        cov, dof, more = _jackknife(est, data, 2 * L, workers)
        single = more.pop("single_block_columns")
        details.update(more)
        label = (lambda i: str(names[i]) if names is not None else str(i))
        shown = (lambda i: names is None or names[i] in reported)
        few = [i for i in np.flatnonzero(dof < MIN_DOF) if shown(i) and i not in single]
        alone = [label(i) for i in single if shown(i)]
        if alone:
            warnings += (f"uncertainty: {', '.join(alone)} are determined by one block of {2 * L} samples alone "
                         f"(leverage {more['max_block_leverage']:.2f}); their std cannot be estimated from the "
                         "data's scatter and may be far too small: drive those segments longer or repeat them",)
        if few:
            warnings += (f"uncertainty: the std of {', '.join(f'{label(i)} ({dof[i]:.1f})' for i in few)} rests on "
                         f"few blocks of {2 * L} samples (degrees of freedom in brackets; largest block leverage "
                         f"{more['max_block_leverage']:.2f}): their 95 % intervals use Student's t; drive those "
                         "segments longer or repeat them",)
    else:
        cov = _bootstrap(est, data, L, replicates, seed)
        details.update(replicates=replicates, block_steps=L, seed=seed)
    active = getattr(est, "active_", ())
    if active:  # parameters held by a bound: no spread from the data
        fixed = np.all(est.bread_ == 0, axis=1)
        cov[fixed, :] = 0.0
        cov[:, fixed] = 0.0
    return Uncertainty(method, cov, details, warnings, dof)
