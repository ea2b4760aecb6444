"""Did m_ch or C_ch change within a recording? A split test on the identification's rows (issue 31, item 0).

An identification averages a recording in which the load changed (it is the same least-squares
fit either way). The test asks, for every candidate time ``tau`` on a grid, whether letting m_ch and
C_ch take other values from ``tau`` on explains the residuals: the score (Lagrange multiplier)
test of adding the two columns ``X_2(tau) = [phi_m, phi_C] 1(t >= tau)`` to the fitted regression
``y = X p + e``:

    b(tau) = X_2^T W e,    A(tau) = X_2^T W X_2 - X_2^T W X (X^T W X)^-1 X^T W X_2,    T(tau) = b^T A^-1 b,

all from cumulative sums over the rows in time order (O(N) per recording). The rows are weighted by
``1 / (sigma_c^2 n_corr,c)`` of their class (motion mode x coordinate): ``sigma_c^2`` the residual
variance of the class and ``n_corr,c = 1 + 2 sum rho_l`` its residuals' correlation length (the
chassis rows of filtered signals stay correlated over ~1.5 s on the simulator: without it the test
fires on every log), and the fit is redone with these weights before the scan, so that
``T(tau)`` is chi^2 with 2 dof (1 where one parameter has less than ``min_information`` of its
information on a side) without a change. The largest ``T`` names the time, ``delta = A^-1 b`` is the
step in (m_ch, C_ch) with the std ``sqrt(diag(A^-1))``. A change is reported when ``max T`` exceeds
``threshold`` (default 8; the effect-free identification logs of seeds 1-3 give at most 1.6 and a
+250 kg pick-up in the middle of the straight segment 16.7, tests/test_online.py) and the step is at
least ``min_relative`` of the value.

Each recording (``EquationBlock.recording``: one continuous log) is tested on its own; only the
chassis rows carry m_ch and C_ch: :func:`parameter_change` projects on every kept row,
:func:`parameter_change_in_store` (what ``identify`` runs, on the rows its fit keeps) on the chassis
rows alone, at half the cost.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.determinacy import std_from_covariance
from agvdyn.identification.equations import EquationBlock
from agvdyn.platform import PARAMETER_NAMES

__all__ = ["ParameterChange", "parameter_change", "parameter_change_in_store"]

_TRACKED = ("m_ch", "C_ch")


@dataclass(frozen=True)
class ParameterChange:
    """A change found within a recording: its time ``t`` (s, the recording's clock), the statistic,
    and the step ``size`` of m_ch and C_ch (after minus before) with its ``std`` (None for a parameter
    the split does not test: no information on one side)."""

    recording: str
    t: float
    statistic: float
    threshold: float
    size: dict[str, float | None]
    std: dict[str, float | None]
    before: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {"recording": self.recording, "t": self.t, "statistic": self.statistic, "threshold": self.threshold,
                "size": dict(self.size), "std": dict(self.std), "before": dict(self.before),
                "hint": "the chassis equations change within the recording: a load change (identify each part "
                        "alone, or follow it with 'agvdyn track', docs/online.md), or another effect the model "
                        "lacks (wheel slip, a drive fault)"}


def _stack(blocks: Sequence[EquationBlock], offsets: bool) -> tuple[np.ndarray, ...]:
    """Kept rows of the blocks in time order: t (n,), X (n, p), y (n,) and each row's class (n,)
    (motion mode x coordinate: rows of one class share a noise level)."""
    t, X, y, cls = [], [], [], []
    for b in blocks:
        keep = b.keep
        cols = [b.regressor[keep]]
        if offsets:
            cols.append(b.offset_regressor[keep])
        X.append(np.concatenate(cols, axis=1))
        y.append(b.torque[keep])
        t.append(np.broadcast_to(b.t[:, None], keep.shape)[keep])
        cls.append(np.broadcast_to(10 * int(b.mode) + np.arange(keep.shape[1]), keep.shape)[keep])
    t, X, y, cls = (np.concatenate(a) for a in (t, X, y, cls))
    order = np.argsort(t, kind="stable")
    return t[order], X[order], y[order], cls[order]


def _weights(e: np.ndarray, cls: np.ndarray) -> np.ndarray:
    """1 / (sigma_c^2 n_corr,c) of each row's class: its residual variance times its correlation length."""
    w = np.zeros(e.size)
    for c in np.unique(cls):
        sel = cls == c
        ec = e[sel]
        var = float(ec @ ec) / max(ec.size, 1)
        w[sel] = 1.0 / (var * _correlation_length(ec)) if var > 0 and ec.size > 10 else 0.0
    return w


def _correlation_length(e: np.ndarray, max_lag: int = 400) -> float:
    """``1 + 2 sum rho_l`` of the residual series, summed until rho first drops below 0.05."""
    from agvdyn.identification.correlation import autocovariance_sums

    c = autocovariance_sums(e[:, None])[: max_lag + 1, 0]
    rho = c / c[0]
    below = np.flatnonzero(rho < 0.05)
    stop = int(below[0]) if below.size else rho.size
    return float(1.0 + 2.0 * rho[1:stop].sum())


def _tail_sums(idx: np.ndarray, n: int, terms, chunk: int = 1 << 16) -> np.ndarray:
    """``sum_{r >= i} terms(r)`` at each row index i of ``idx`` (ascending), the per-row terms formed
    ``chunk`` rows at a time by ``terms(slice)``: rows are summed per interval between grid indices
    (``np.add.reduceat``), then the intervals from the end (memory and work of the grid, not one
    cumulative array per row)."""
    S = None
    for a in range(0, n, chunk):
        T = terms(slice(a, min(n, a + chunk)))
        k = np.searchsorted(idx, np.arange(a, a + T.shape[0]), side="right")  # grid indices <= the row
        starts = np.flatnonzero(np.diff(k, prepend=-1))
        if S is None:
            S = np.zeros((idx.size + 1,) + T.shape[1:])
        S[k[starts]] += np.add.reduceat(T, starts, axis=0)
    tail = np.cumsum(S[::-1], axis=0)[::-1]  # tail[j]: rows with more than j grid indices at or before them
    return tail[1:]


def _scan(t: np.ndarray, X: np.ndarray, e: np.ndarray, w: np.ndarray, cols: list[int], step: float, guard: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate times, b (m, 2) and A (m, 2, 2) of the weighted score test at each (``e`` the
    weighted fit's residuals, ``w`` the row weights)."""
    Z = X[:, cols]
    Zw = Z * w[:, None]
    G = np.linalg.pinv(X.T @ (X * w[:, None]))
    grid = np.arange(t[0] + guard, t[-1] - guard, step)
    idx = np.searchsorted(t, grid)
    if grid.size == 0:
        return grid, np.zeros((0, 2)), np.zeros((0, 2, 2))
    zz = _tail_sums(idx, t.size, lambda r: np.einsum("ni,nj->nij", Zw[r], Z[r]))
    zx = _tail_sums(idx, t.size, lambda r: np.einsum("ni,nj->nij", Zw[r], X[r]))
    b = _tail_sums(idx, t.size, lambda r: Zw[r] * e[r, None])
    A = zz - np.einsum("mip,pq,mjq->mij", zx, G, zx)
    return grid, b, A


def _split_inverse(A: np.ndarray, total: np.ndarray, min_information: float) -> np.ndarray:
    """Inverse of each A (m, 2, 2) restricted to the parameters it determines: a parameter whose
    information after the split, net of the fit, is below ``min_information`` of its total (no rows
    of it on one side) is left out (its row and column zero), so the test has 2, 1 or 0 dof."""
    inv = np.zeros_like(A)
    diag = np.diagonal(A, axis1=1, axis2=2)
    use = (diag >= min_information * total) & (diag > 0)  # none of a parameter's rows in the recording: untested
    both = use[:, 0] & use[:, 1]
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] ** 2
    both &= det > 1e-9 * A[:, 0, 0] * A[:, 1, 1]
    inv[both, 0, 0], inv[both, 1, 1] = A[both, 1, 1] / det[both], A[both, 0, 0] / det[both]
    inv[both, 0, 1] = inv[both, 1, 0] = -A[both, 0, 1] / det[both]
    for i in range(2):
        one = use[:, i] & ~both
        inv[one, i, i] = 1.0 / A[one, i, i]
    return inv


def _test(name: str, t: np.ndarray, X: np.ndarray, y: np.ndarray, cls: np.ndarray, coef: np.ndarray,
          cols: list[int], threshold: float, min_relative: float, step: float, guard: float,
          min_information: float) -> ParameterChange | None:
    """The split test of one recording's kept rows (time order), ``coef`` the identification's estimate."""
    if t.size < 100 or t[-1] - t[0] <= 2 * guard + step:
        return None
    w = _weights(y - X @ coef, cls)
    Xw = X * w[:, None]
    fitted = np.linalg.lstsq(X.T @ Xw, Xw.T @ y, rcond=None)[0]  # the weighted fit the test extends
    e = y - X @ fitted
    grid, b, A = _scan(t, X, e, w, cols, step, guard)
    if grid.size == 0:
        return None
    inv = _split_inverse(A, np.einsum("ni,ni->i", X[:, cols] * w[:, None], X[:, cols]), min_information)
    stat = np.einsum("mi,mij,mj->m", b, inv, b)
    k = int(np.argmax(stat))
    delta = inv[k] @ b[k]
    std = std_from_covariance(inv[k], list(_TRACKED))[0]  # a negative variance is inf, never 0
    value = coef[cols]
    tested = np.diagonal(inv[k]) > 0
    if not (stat[k] > threshold and (tested & (np.abs(delta) >= min_relative * np.abs(value))).any()):
        return None
    # a parameter without information on one side is not tested there: no size, no std
    return ParameterChange(name, float(grid[k]), float(stat[k]), threshold,
                           {n: float(d) if u else None for n, d, u in zip(_TRACKED, delta, tested)},
                           {n: float(e) if u else None for n, e, u in zip(_TRACKED, std, tested)},
                           dict(zip(_TRACKED, value.tolist())))


def parameter_change(blocks: Sequence[EquationBlock], parameters: np.ndarray, *, offsets: np.ndarray | None = None,
                     threshold: float = 8.0, min_relative: float = 0.03, step: float = 0.1, guard: float = 2.0,
                     min_information: float = 0.15) -> list[ParameterChange]:
    """The m_ch / C_ch change found in each recording of an identification's ``blocks`` (module
    docstring): ``parameters`` (11,) the estimate of eq. (18), ``offsets`` (4,) the motor-torque offsets
    when they were estimated. ``step`` s between candidate times; none within ``guard`` s of a
    recording's ends; a parameter with less than ``min_information`` of its information on either
    side of a candidate is not tested there. Returns one :class:`ParameterChange` per recording with a change (empty: none)."""
    p = np.asarray(parameters, dtype=float)
    coef = p if offsets is None else np.concatenate([p, offsets])
    cols = [PARAMETER_NAMES.index(n) for n in _TRACKED]
    by_recording: dict[str, list[EquationBlock]] = {}
    for b in blocks:
        by_recording.setdefault(b.recording, []).append(b)
    found = (_test(name, *_stack(group, offsets is not None), coef, cols, threshold, min_relative, step, guard,
                   min_information) for name, group in by_recording.items())
    return [c for c in found if c is not None]


def parameter_change_in_store(store: Any, theta: np.ndarray, timing: Sequence[tuple[str, float, float]], *,
                              rows: Sequence[int] | None = None, workers: int = 1, threshold: float = 8.0,
                              min_relative: float = 0.03, step: float = 0.1, guard: float = 2.0,
                              min_information: float = 0.15) -> list[ParameterChange]:
    """:func:`parameter_change` on the rows an identification keeps per continuous recording (its
    :class:`~agvdyn.identification.store.RowStore`, read back one recording at a time, so memory stays
    that of the fit): ``theta`` the full estimate (11 parameters, then the offsets when the store has
    their columns), ``timing`` per recording its log's name, first time and nominal sample time (a
    row's time is ``t0 + step * dt``: the log's clock where it has no dropout). ``rows``: the group codes
    of the rows tested (None: all); :func:`identify` tests the chassis rows, the only ones that carry
    m_ch and C_ch (the steering rows would only sharpen the other parameters, at twice the cost).
    The recordings are tested in up to ``workers`` threads."""
    from agvdyn.identification._threads import ordered_map

    theta = np.asarray(theta, dtype=float)
    cols = [PARAMETER_NAMES.index(n) for n in _TRACKED]

    def test(job: tuple[Any, tuple[str, float, float]]) -> ParameterChange | None:
        rows_of, (name, t0, dt) = job
        rec = rows_of()
        order = np.argsort(rec.step, kind="stable")
        if rows is not None:
            order = order[np.isin(rec.group[order], rows)]
        cls = rec.group if rec.key is None else rec.key
        return _test(name, t0 + rec.step[order] * dt, rec.A[order], rec.y[order], cls[order], theta, cols,
                     threshold, min_relative, step, guard, min_information)

    jobs = zip(store.free_jobs(list(range(theta.size)), np.zeros(theta.size)), timing)
    return [c for c in ordered_map(test, jobs, workers, "agvdyn-change") if c is not None]
