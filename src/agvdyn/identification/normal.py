"""The stacked system of eq. (22) without stacking: per log, the kept rows are reduced to the
triangular factor ``R`` of ``[Theta_hat | tau_hat]`` per segment and generalized coordinate
(``R^T R`` is their Gram block, the normal matrix, without the round-off of forming it), and the rows themselves go to a compact store (spilled to
disk beyond a memory budget) that only the HAC and bootstrap covariances read back, one
continuous recording at a time. Many logs then cost one small solve, and memory does not grow
with the number of logs.

The factors of all keys, with the fixed parameters moved to the right (eq. 24), are
*pseudo-rows*: a few rows per key with the normal equations, column norms, QR factor and
per-coordinate residual sums of squares of the full stacked rows. Solving on them gives the
stacked answer to round-off (forming the Gram matrix instead would square the condition number). The estimators that need
no single residual (``ols``, ``wls``, ``bounded``) solve on them the same problem as on the rows.
"""
from __future__ import annotations

import dataclasses
import shutil
import tempfile
import weakref
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agvdyn.dynamics import N_P
from agvdyn.identifiability import triangular_factor
from agvdyn.identification._kernels import kept_rows
from agvdyn.identification.equations import EquationBlock

#: Rows per QR of a tall-skinny factorization (fits the caches; fewer calls than more rows).
_QR_ROWS = 2048

__all__ = ["RowIndex", "RowStore", "RecordingRows", "RowStatistics", "RegressionData", "row_statistics", "regression_data",
           "stacked_regression_data"]


@dataclass(frozen=True, eq=False)
class RowIndex:
    """Where each stacked row comes from: generalized coordinate ``group`` (codes into
    ``group_names``), ``recording`` (codes) and time ``step`` (sample index in the recording)."""

    group: np.ndarray
    group_names: tuple[str, ...]
    recording: np.ndarray
    step: np.ndarray


@dataclass(frozen=True, eq=False)
class RecordingRows:
    """Kept rows of one continuous recording: ``A`` (m, w) full regressor (parameters and offset
    columns), ``y`` (m,), ``group`` (m,) coordinate codes, ``step`` (m,) sample index, ``key``
    (m,) codes of their (segment, coordinate) in the order of :class:`RowStatistics`."""

    A: np.ndarray
    y: np.ndarray
    group: np.ndarray
    step: np.ndarray
    key: np.ndarray | None = None


class RowStore:
    """Rows per continuous recording; past ``budget`` bytes in memory they go to a temporary folder
    (removed with the store). Iterating yields :class:`RecordingRows` in the order added.

    :meth:`add_packed` takes rows as they come from :func:`row_statistics`, one ``[A | y]`` block
    (views are kept as they are: no copy; a spilled block is written as one plain array)."""

    def __init__(self, budget: int = 64 << 20) -> None:
        self.budget = budget
        self._items: list[RecordingRows | _Packed | tuple[Path, Path]] = []
        self._bytes = 0
        self._folder: Path | None = None
        self._cleanup: weakref.finalize | None = None

    def add(self, rows: RecordingRows) -> None:
        self.add_packed(np.column_stack([rows.A, rows.y]), rows.group, rows.step, rows.key)

    def add_packed(self, rows: np.ndarray, group: np.ndarray, step: np.ndarray, key: np.ndarray | None) -> None:
        """Rows ``[A | y]`` (m, w + 1) of one recording with their coordinate codes, steps and keys."""
        size = sum(x.nbytes for x in (rows, group, step, key) if x is not None)
        if self._bytes + size <= self.budget:
            self._items.append(_Packed(rows, group, step, key))
            self._bytes += size
            return
        if self._folder is None:
            self._folder = Path(tempfile.mkdtemp(prefix="agvdyn-rows-"))
            self._cleanup = weakref.finalize(self, shutil.rmtree, self._folder, True)
        base = self._folder / str(len(self._items))  # plain arrays: no zip on the way back
        codes = np.empty((rows.shape[0], 3), dtype=np.int64)
        codes[:, 0], codes[:, 1] = group, step
        codes[:, 2] = -1 if key is None else key
        np.save(f"{base}.rows.npy", np.ascontiguousarray(rows))
        np.save(f"{base}.codes.npy", codes)
        self._items.append((Path(f"{base}.rows.npy"), Path(f"{base}.codes.npy")))

    def packed(self) -> Iterator[_Packed]:
        """The stored recordings as ``[A | y]`` blocks (read back from disk when spilled)."""
        for item in self._items:
            if isinstance(item, tuple):
                rows, codes = np.load(item[0]), np.load(item[1])
                key = codes[:, 2].astype(np.int16)
                yield _Packed(rows, codes[:, 0].astype(np.int8), codes[:, 1],
                              None if key.size and key[0] < 0 else key)
            else:
                yield item

    def __iter__(self) -> Iterator[RecordingRows]:
        for p in self.packed():
            yield RecordingRows(p.rows[:, :-1], p.rows[:, -1], p.group, p.step, p.key)

    def __len__(self) -> int:
        return len(self._items)

    @property
    def spilled(self) -> int:
        return sum(isinstance(i, tuple) for i in self._items)

    def close(self) -> None:
        if self._cleanup is not None:
            self._cleanup()
        self._items.clear()


@dataclass(frozen=True, eq=False)
class _Packed:
    rows: np.ndarray
    group: np.ndarray
    step: np.ndarray
    key: np.ndarray | None


@dataclass
class RowStatistics:
    """Per (segment, coordinate), in the order first seen: the triangular factor ``R`` of its rows
    ``[A | y]`` (``R^T R`` is their normal matrix, without the round-off of forming it) and the
    row count. ``width``: columns of A (11 parameters, plus 4 offsets)."""

    width: int
    factors: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)
    counts: dict[tuple[str, str], int] = field(default_factory=dict)

    def add(self, key: tuple[str, str], rows: np.ndarray) -> None:
        """Merge rows ``[A | y]`` (m, width + 1) into the factor of ``key`` (tall-skinny QR over the
        columns that are not zero in the rows or the factor: a key's rows leave most columns zero)."""
        if rows.shape[0] == 0:
            return
        old = self.factors.get(key)
        used = np.abs(rows).max(axis=0) > 0
        if old is not None:
            used |= np.abs(old).max(axis=0) > 0
        cols = np.flatnonzero(used)
        parts = [np.linalg.qr(rows[i:i + _QR_ROWS][:, cols], mode="r") for i in range(0, rows.shape[0], _QR_ROWS)]
        if old is not None:
            parts.append(old[:, cols])
        stacked = np.vstack(parts) if len(parts) > 1 else parts[0]
        R = np.zeros((self.width + 1, self.width + 1))
        r = np.linalg.qr(stacked, mode="r") if len(parts) > 1 else stacked
        R[np.ix_(np.arange(r.shape[0]), cols)] = r
        self.factors[key] = R
        self.counts[key] = self.counts.get(key, 0) + rows.shape[0]

    @property
    def n_rows(self) -> int:
        return sum(self.counts.values())

    def key_code(self, key: tuple[str, str]) -> int:
        """Position of ``key`` among the keys (a new key gets the next one)."""
        codes = self.__dict__.setdefault("_codes", {})
        if key not in self.factors:
            self.factors[key] = np.zeros((self.width + 1, self.width + 1))
            self.counts[key] = 0
        if key not in codes:
            codes.update((k, i) for i, k in enumerate(self.factors))
        return codes[key]

    def factor(self, key: tuple[str, str]) -> np.ndarray:
        """Pseudo-rows ``R`` (width + 1, width + 1) of ``key``: ``R^T R`` is the normal matrix of its rows."""
        return self.factors[key]


def row_statistics(blocks: Sequence[EquationBlock], stats: RowStatistics, store: RowStore | None,
                   group_names: dict[str, int], *, offsets: bool) -> None:
    """Add the kept rows of ``blocks`` (one log) to ``stats`` and, per recording, to ``store``.

    The kept rows ``[H_k^T Theta | H_k^T B | H_k^T B u]`` of all blocks are gathered in one array
    (:func:`._kernels.kept_rows`; per block, coordinate by coordinate, in time order); the rows of
    each (segment, coordinate) are merged into its triangular factor, those of each recording go
    to the store as they lie in the array."""
    plan, total = [], 0
    for b in blocks:
        counts = np.count_nonzero(b.keep, axis=0)
        if not counts.any():
            continue
        key = np.full(len(b.coordinates), -1, dtype=np.int16)
        group = np.zeros(len(b.coordinates), dtype=np.int8)
        for j, coord in enumerate(b.coordinates):
            if counts[j]:
                group[j] = group_names.setdefault(coord, len(group_names))
                key[j] = stats.key_code((b.segment, coord))
        plan.append((b, key, group, int(counts.sum())))
        total += int(counts.sum())
    if not total:
        return
    rows = np.empty((total, stats.width + 1))
    key, step, group = np.empty(total, np.int16), np.empty(total, np.int64), np.empty(total, np.int8)
    start, recordings = 0, []
    for b, key_of, group_of, m in plan:
        offs = b.offset_regressor if offsets else np.zeros((0, 1, 4))
        kept_rows(b.regressor, offs, b.torque, b.keep, b.sample, group_of, key_of, offsets,
                  rows[start:start + m], key[start:start + m], step[start:start + m], group[start:start + m])
        if recordings and recordings[-1][0] == b.recording:
            recordings[-1][2] = start + m
        else:
            recordings.append([b.recording, start, start + m])
        start += m
    order = np.argsort(key, kind="stable")
    ordered = rows[order]
    bounds = np.flatnonzero(np.diff(key[order])) + 1
    names = list(stats.factors)
    for a, e in zip(np.concatenate([[0], bounds]).tolist(), np.concatenate([bounds, [total]]).tolist()):
        stats.add(names[int(key[order[a]])], ordered[a:e])
    if store is None:
        return
    for _, a, e in recordings:
        store.add_packed(rows[a:e], group[a:e], step[a:e], key[a:e])


@dataclass(frozen=True, eq=False)
class RegressionData:
    """What the regression of eq. (24) works on: ``A`` (rows, free) and ``y`` (rows,) with the
    fixed parameters moved to the right, either the stacked rows themselves or pseudo-rows with
    the same normal equations (``pseudo``). ``group`` codes into ``group_names`` per row,
    ``group_rows``: number of stacked rows per group; ``n_rows``: of the stacked system.
    ``keys``: the (segment, coordinate) pairs, ``key_rows`` their stacked rows, ``key_pseudo``
    their pseudo-rows ``[A | y]`` (for the residual RMS per key). ``store``: the stacked rows per recording (full width), for the covariances that need them.
    """

    A: np.ndarray
    y: np.ndarray
    group: np.ndarray
    group_names: tuple[str, ...]
    group_rows: np.ndarray
    n_rows: int
    pseudo: bool
    free: tuple[int, ...]
    theta_fixed: np.ndarray
    keys: tuple[tuple[str, str], ...] = ()
    key_rows: tuple[int, ...] = ()
    key_pseudo: tuple[np.ndarray, ...] = ()
    store: RowStore | None = None
    row_order: np.ndarray | None = None  # rows of A in the store's order, when they differ

    def residual_rms(self, coef: np.ndarray) -> dict[str, float]:
        """RMS of tau - Theta p per "segment:coordinate" (pooled over logs): from the stored rows
        (exact), else from the pseudo-rows (to about 1e-8 of the torques)."""
        if self.store is not None and all(rec.key is not None for rec in self.store):
            sums = np.zeros(len(self.keys))
            for rec in self.recordings():
                r = rec.y - rec.A @ coef
                sums += np.bincount(rec.key, weights=r * r, minlength=len(self.keys))
        else:
            x = np.append(coef, -1.0)
            sums = np.array([float((P @ x) @ (P @ x)) for P in self.key_pseudo])
        return {f"{k[0]}:{k[1]}": float(np.sqrt(s / n)) for k, n, s in zip(self.keys, self.key_rows, sums) if n}

    @classmethod
    def from_rows(cls, A: np.ndarray, y: np.ndarray, index: RowIndex) -> "RegressionData":
        """Stacked rows ``A`` (m, p), ``y`` with their :class:`RowIndex`; every column free."""
        A, y = np.asarray(A, dtype=float), np.asarray(y, dtype=float)
        store = RowStore(budget=1 << 62)
        order = np.argsort(index.recording, kind="stable")
        bounds = np.flatnonzero(np.diff(index.recording[order])) + 1
        for sel in np.split(order, bounds) if order.size else []:
            store.add(RecordingRows(A[sel], y[sel], index.group[sel], index.step[sel]))
        p = A.shape[1]
        return cls(A, y, index.group, index.group_names, np.bincount(index.group, minlength=len(index.group_names)),
                   A.shape[0], False, tuple(range(p)), np.zeros(p), store=store, row_order=order)

    def holding(self, columns: Sequence[int], values: np.ndarray) -> "RegressionData":
        """The same system with the free columns at positions ``columns`` held at ``values`` (moved
        to the right like the fixed parameters of eq. 24)."""
        keep = [i for i in range(len(self.free)) if i not in set(columns)]
        held = [self.free[i] for i in columns]
        theta_fixed = self.theta_fixed.copy()
        theta_fixed[held] = values
        shift = self.A[:, list(columns)] @ np.asarray(values, dtype=float)
        pseudo = tuple(np.column_stack([P[:, keep], P[:, -1] - P[:, list(columns)] @ values]) for P in self.key_pseudo)
        return dataclasses.replace(self, A=self.A[:, keep], y=self.y - shift, free=tuple(self.free[i] for i in keep),
                                   theta_fixed=theta_fixed, key_pseudo=pseudo)

    def theta(self, coef: np.ndarray) -> np.ndarray:
        """All columns' values (fixed ones as given) from the free ones."""
        theta = self.theta_fixed.copy()
        theta[list(self.free)] = coef
        return theta

    def group_rss(self, coef: np.ndarray) -> np.ndarray:
        """Residual sum of squares per group over the stored rows (exact, where the pseudo-rows lose
        digits to cancellation when the fit is close)."""
        total = np.zeros(len(self.group_names))
        for rec in self.recordings():
            r = rec.y - rec.A @ coef
            total += np.bincount(rec.group, weights=r * r, minlength=total.size)
        return total

    def stacked(self) -> "RegressionData":
        """The same system with every stored row in memory (for estimators that weigh single rows)."""
        if self.store is None:
            raise RuntimeError("these regression data keep no rows")
        recs = list(self.recordings())
        A = np.vstack([r.A for r in recs]) if recs else np.zeros((0, len(self.free)))
        y = np.concatenate([r.y for r in recs]) if recs else np.zeros(0)
        group = np.concatenate([r.group for r in recs]).astype(np.int64) if recs else np.zeros(0, np.int64)
        return dataclasses.replace(self, A=A, y=y, group=group, pseudo=False, row_order=None,
                                   group_rows=np.bincount(group, minlength=len(self.group_names)))

    def recordings(self) -> Iterator[RecordingRows]:
        """Rows of each recording with the free columns only and ``y`` as in eq. (24)."""
        if self.store is None:
            raise RuntimeError("these regression data keep no rows")
        free = list(self.free)
        for rec in self.store:
            yield RecordingRows(rec.A[:, free], rec.y - rec.A @ self.theta_fixed, rec.group, rec.step, rec.key)


def regression_data(stats: RowStatistics, group_names: dict[str, int], free: Sequence[int], theta_fixed: np.ndarray,
                    store: RowStore | None) -> RegressionData:
    """Pseudo-rows ``R_key T`` of every key, ``T`` taking ``[A | y]`` to ``[A_free | y - A theta_fixed]``."""
    width = stats.width
    T = np.zeros((width + 1, len(free) + 1))
    T[list(free), np.arange(len(free))] = 1.0
    T[:width, -1] = -theta_fixed
    T[width, -1] = 1.0
    blocks, codes, rows = [], [], []
    group_rows = np.zeros(len(group_names), dtype=np.int64)
    for key in stats.factors:
        P = stats.factor(key) @ T
        blocks.append(P)
        code = group_names[key[1]]
        codes.append(np.full(P.shape[0], code, np.int64))
        rows.append(stats.counts[key])
        group_rows[code] += stats.counts[key]
    P = np.vstack(blocks) if blocks else np.zeros((0, len(free) + 1))
    return RegressionData(P[:, :-1], P[:, -1], np.concatenate(codes) if codes else np.zeros(0, np.int64),
                          tuple(group_names), group_rows, stats.n_rows, True, tuple(free), theta_fixed,
                          tuple(stats.factors), tuple(rows), tuple(blocks), store)


def stacked_regression_data(blocks: Sequence[EquationBlock], free: Sequence[int], theta_fixed: np.ndarray, *,
                            offsets: bool) -> RegressionData:
    """The reference: all kept rows stacked (eq. 22), in memory, as :func:`regression_data` sees them."""
    stats = RowStatistics(N_P + (4 if offsets else 0))
    store = RowStore(budget=1 << 62)
    names: dict[str, int] = {}
    row_statistics(blocks, stats, store, names, offsets=offsets)
    return regression_data(stats, names, free, theta_fixed, store).stacked()
