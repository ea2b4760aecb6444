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
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from agvdyn.dynamics import N_P
from agvdyn.identification._kernels import kept_rows
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.store import RecordingRows, RowStore
from agvdyn.identification.workspace import Workspace, empty

__all__ = ["RowIndex", "RowStore", "RecordingRows", "RowStatistics", "RegressionData", "LogReduction", "row_statistics",
           "reduce_blocks", "merge_reduction", "regression_data", "stacked_regression_data", "triangular_rows"]


@dataclass(frozen=True, eq=False)
class RowIndex:
    """Where each stacked row comes from: generalized coordinate ``group`` (codes into
    ``group_names``), ``recording`` (codes) and time ``step`` (sample index in the recording)."""

    group: np.ndarray
    group_names: tuple[str, ...]
    recording: np.ndarray
    step: np.ndarray


#: Factors of one key stacked before they are merged into its running factor by one QR.
_MERGE_BATCH = 32


@dataclass
class RowStatistics:
    """Per (segment, coordinate), in the order first seen: the triangular factor ``R`` of its rows
    ``[A | y]`` (``R^T R`` is their normal matrix, without the round-off of forming it) and the
    row count. ``width``: columns of A (11 parameters, plus 4 offsets)."""

    width: int
    factors: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)
    counts: dict[tuple[str, str], int] = field(default_factory=dict)
    #: natural column of each column of the rows as added (None: natural order); factors are
    #: kept in that order, :meth:`factor` returns them in the natural one
    columns: np.ndarray | None = None
    #: factors added per key and not yet merged (see :meth:`add`)
    _pending: dict[tuple[str, str], list[np.ndarray]] = field(default_factory=dict, repr=False)

    def add(self, key: tuple[str, str], rows: np.ndarray, count: int | None = None) -> None:
        """Merge rows ``[A | y]`` (m, width + 1) into the factor of ``key`` (QR over the
        columns that are not zero in the rows or the factor: a key's rows leave most columns zero).
        ``count``: the rows they stand for when they are themselves a factor (default m); factors
        are merged a batch at a time (one QR per :data:`_MERGE_BATCH` logs instead of one per log)."""
        if rows.shape[0] == 0:
            return
        self.factors.setdefault(key, np.zeros((self.width + 1, self.width + 1)))
        self.counts[key] = self.counts.get(key, 0) + (rows.shape[0] if count is None else count)
        pending = self._pending.setdefault(key, [])
        pending.append(rows)
        if count is None or len(pending) >= _MERGE_BATCH:
            self._merge(key)

    def _merge(self, key: tuple[str, str]) -> None:
        pending = self._pending.pop(key, [])
        if not pending:
            return
        old = self.factors[key]
        self.factors[key] = triangular_rows(np.vstack(pending), self.width + 1, old if old.any() else None)

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
        self._merge(key)
        R = self.factors[key]
        if self.columns is None:
            return R
        out = np.empty_like(R)
        out[:, np.append(self.columns, self.width)] = R
        return out


def triangular_rows(rows: np.ndarray, size: int, old: np.ndarray | None = None,
                    used: np.ndarray | None = None) -> np.ndarray:
    """Triangular factor (size, size) of ``rows`` (m, size) stacked on ``old`` (a factor): one
    Householder QR (LAPACK ``dgeqrf``) over the columns that are not zero anywhere (the others stay
    zero; ``used``: the rows' columns not zero, when known)."""
    used = np.abs(rows).max(axis=0) > 0 if used is None else used.copy()
    if old is not None:
        used |= np.abs(old).max(axis=0) > 0
    cols = np.flatnonzero(used)
    # gathered column by column into a Fortran-ordered array (numpy's QR works on a copy of it)
    a = rows.T[cols].T if old is None else np.asfortranarray(np.vstack([rows[:, cols], old[:, cols]]))
    R = np.zeros((size, size))
    if a.shape[0] == 0 or cols.size == 0:
        return R
    # numpy's QR is LAPACK's dgeqrf (the same R, bit for bit, as scipy's, without scipy.linalg's import)
    R[:min(a.shape), cols] = np.linalg.qr(a, mode="r")
    return R


@dataclass(frozen=True, eq=False)
class LogReduction:
    """The kept rows of one log's blocks, reduced without shared state (threads may build several
    at once; :func:`merge_reduction` adds them in log order). ``keys`` (segment, coordinate) and
    ``groups`` (coordinate names) in the order first seen, ``factors``/``counts`` per key,
    ``rows`` ``[A | y]`` with A's columns in the stored order, ``key``/``group`` codes into the
    local lists, ``step``; ``recordings`` (name, start, stop) row ranges."""

    keys: tuple[tuple[str, str], ...]
    groups: tuple[str, ...]
    factors: tuple[np.ndarray, ...]
    counts: tuple[int, ...]
    rows: np.ndarray
    key: np.ndarray
    group: np.ndarray
    step: np.ndarray
    recordings: tuple[tuple[str, int, int], ...]


def reduce_blocks(blocks: Sequence[EquationBlock], width: int, *, offsets: bool,
                  columns: np.ndarray | None = None, workspace: Workspace | None = None) -> LogReduction:
    """The kept rows ``[H_k^T Theta | H_k^T B | X | H_k^T B u]`` of ``blocks`` (one log; the offsets'
    ``H_k^T B`` with ``offsets``, a model extension's columns X when the blocks carry them) gathered in one
    array (:func:`._kernels.kept_rows`; per block, coordinate by coordinate, in time order) and
    the triangular factor of each (segment, coordinate)."""
    keys: dict[tuple[str, str], int] = {}
    groups: dict[str, int] = {}
    plan, per_key = [], []
    for b in blocks:
        # column by column: count_nonzero(axis=0) of a strided (m, 2) bool view is ~17x slower
        counts = np.array([np.count_nonzero(b.keep[:, j]) for j in range(b.keep.shape[1])])
        if not counts.any():
            continue
        key = np.full(len(b.coordinates), -1, dtype=np.int16)
        group = np.zeros(len(b.coordinates), dtype=np.int8)
        for j, coord in enumerate(b.coordinates):
            if counts[j]:
                group[j] = groups.setdefault(coord, len(groups))
                key[j] = keys.setdefault((b.segment, coord), len(keys))
                per_key += [0] * (len(keys) - len(per_key))
                per_key[key[j]] += int(counts[j])
        plan.append((b, key, group, int(counts.sum())))
    total = sum(per_key)
    rows = np.empty((total, width + 1))
    by_key = empty(workspace, "by_key", rows.shape)
    ends = np.cumsum(per_key, dtype=np.int64)
    cursor = ends - np.asarray(per_key, dtype=np.int64)
    starts = cursor.copy()
    key, step, group = np.empty(total, np.int16), np.empty(total, np.int64), np.empty(total, np.int8)
    column = np.arange(width) if columns is None else np.argsort(columns)
    start, recordings = 0, []
    nonzero = np.zeros((len(per_key), width + 1), dtype=bool)
    for b, key_of, group_of, m in plan:
        extra = _extra_columns(b, offsets)
        if N_P + extra.shape[2] != width:  # the kernel writes where the columns say: never past the row
            raise ValueError(f"{b.source}: block {b.segment!r} has {N_P + extra.shape[2]} columns, the rows "
                             f"{width}: the rows were made for another model or offset setting")
        kept_rows(b.regressor, extra, b.torque, b.keep, b.sample, group_of, key_of, column,
                  rows[start:start + m], key[start:start + m], step[start:start + m], group[start:start + m],
                  by_key, cursor, nonzero)
        if recordings and recordings[-1][0] == b.recording:
            recordings[-1][2] = start + m
        else:
            recordings.append([b.recording, start, start + m])
        start += m
    factors = tuple(triangular_rows(by_key[a:e], width + 1, used=nonzero[i])
                    for i, (a, e) in enumerate(zip(starts.tolist(), ends.tolist())))
    counts = tuple(per_key)
    return LogReduction(tuple(keys), tuple(groups), factors, counts, rows, key, group, step,
                        tuple(tuple(r) for r in recordings))


_NO_COLUMNS = np.zeros((0, 1, 0))


def _extra_columns(block: EquationBlock, offsets: bool) -> np.ndarray:
    """The columns after the paper's 11 of a block's rows: its motor-torque offsets (``offsets``),
    then its model extension's columns (``model_regressor``), each when present."""
    model = block.model_regressor
    if model is None:
        return block.offset_regressor if offsets else _NO_COLUMNS
    return np.concatenate([block.offset_regressor, model], axis=2) if offsets else model


def merge_reduction(reduction: LogReduction, stats: RowStatistics, store: RowStore | None,
                    group_names: dict[str, int], step_offset: int = 0) -> None:
    """Add a log's reduction to ``stats`` (factors merged per key) and its recordings to ``store``,
    with the key and coordinate codes of the whole identification (in the order first seen);
    ``step_offset`` is added to the rows' steps (a piece of a long log: steps of the whole log)."""
    key_codes = np.array([stats.key_code(k) for k in reduction.keys] or [0], dtype=np.int16)
    group_codes = np.array([group_names.setdefault(g, len(group_names)) for g in reduction.groups] or [0], np.int8)
    for k, R, n in zip(reduction.keys, reduction.factors, reduction.counts):
        stats.add(k, R, count=n)
    if store is None or not reduction.rows.shape[0]:
        return
    key, group = key_codes[reduction.key], group_codes[reduction.group]
    for _, a, e in reduction.recordings:
        step = reduction.step[a:e] if not step_offset else reduction.step[a:e] + step_offset
        store.add_packed(reduction.rows[a:e], group[a:e], step, key[a:e])


def row_statistics(blocks: Sequence[EquationBlock], stats: RowStatistics, store: RowStore | None,
                   group_names: dict[str, int], *, offsets: bool) -> None:
    """Add the kept rows of ``blocks`` (one log) to ``stats`` and, per recording, to ``store``
    (:func:`reduce_blocks`, then :func:`merge_reduction`)."""
    merge_reduction(reduce_blocks(blocks, stats.width, offsets=offsets, columns=stats.columns), stats, store,
                    group_names)


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
    ties: tuple[tuple[int, int], ...] = ()  # (column, free column): one parameter for both (:meth:`tying`)

    def residual_rms(self, coef: np.ndarray) -> dict[str, float]:
        """RMS of tau - Theta p per "segment:coordinate" (pooled over logs): from the stored rows
        (exact), else from the pseudo-rows (to about 1e-8 of the torques)."""
        if self.store is not None and self.store.keys:
            sums = self._residual_sums(coef)[1]
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
        to the right like the fixed parameters of eq. 24); a column tied to a held one is held with it."""
        keep = [i for i in range(len(self.free)) if i not in set(columns)]
        held = [self.free[i] for i in columns]
        theta_fixed = self.theta_fixed.copy()
        theta_fixed[held] = values
        theta_fixed[[c for c, t in self.ties if t in held]] = theta_fixed[[t for _, t in self.ties if t in held]]
        shift = self.A[:, list(columns)] @ np.asarray(values, dtype=float)
        pseudo = tuple(np.column_stack([P[:, keep], P[:, -1] - P[:, list(columns)] @ values]) for P in self.key_pseudo)
        return dataclasses.replace(self, A=self.A[:, keep], y=self.y - shift, free=tuple(self.free[i] for i in keep),
                                   theta_fixed=theta_fixed, key_pseudo=pseudo,
                                   ties=tuple((c, t) for c, t in self.ties if t not in held))

    def tying(self, columns: Sequence[int], targets: Sequence[int]) -> "RegressionData":
        """The same system with the free columns at positions ``columns`` tied to those at ``targets``
        (one parameter for both: each column added to its target's, then dropped; its value the target's)."""
        keep = [i for i in range(len(self.free)) if i not in set(columns)]

        def tied(M: np.ndarray) -> np.ndarray:
            M = M.copy()
            for c, t in zip(columns, targets):
                M[:, t] += M[:, c]
            return M[:, keep + list(range(len(self.free), M.shape[1]))]

        pairs = tuple((self.free[c], self.free[t]) for c, t in zip(columns, targets))
        return dataclasses.replace(self, A=tied(self.A), free=tuple(self.free[i] for i in keep),
                                   key_pseudo=tuple(tied(P) for P in self.key_pseudo), ties=self.ties + pairs)

    def theta(self, coef: np.ndarray) -> np.ndarray:
        """All columns' values (fixed ones as given) from the free ones."""
        theta = self.theta_fixed.copy()
        theta[list(self.free)] = coef
        for column, target in self.ties:
            theta[column] = theta[target]
        return theta

    def group_rss(self, coef: np.ndarray) -> np.ndarray:
        """Residual sum of squares per group over the stored rows (exact, where the pseudo-rows lose
        digits to cancellation when the fit is close)."""
        return self._residual_sums(coef)[0].copy()

    def _residual_sums(self, coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual sums of squares per group and per key over the stored rows (one pass, kept for
        the last ``coef``: the regression asks for both at the same solution)."""
        coef = np.asarray(coef, dtype=float)
        cached = self.__dict__.get("_sums")
        if cached is not None and cached[0].shape == coef.shape and np.array_equal(cached[0], coef):
            return cached[1], cached[2]
        groups, keys = np.zeros(len(self.group_names)), np.zeros(len(self.keys))
        from_factors = self._factor_sums(coef)
        if from_factors is not None:  # no pass over the rows
            keys = from_factors
            for key, value in zip(self.keys, keys):
                groups[self.group_names.index(key[1])] += value
            object.__setattr__(self, "_sums", (coef.copy(), groups, keys))
            return groups, keys
        for rec in self.recordings():
            r = rec.y - rec.A @ coef
            r2 = r * r
            groups += np.bincount(rec.group, weights=r2, minlength=groups.size)
            if rec.key is not None and keys.size:
                keys += np.bincount(rec.key, weights=r2, minlength=keys.size)
        object.__setattr__(self, "_sums", (coef.copy(), groups, keys))
        return groups, keys

    def _factor_sums(self, coef: np.ndarray, min_share: float = 1e-6) -> np.ndarray | None:
        """Residual sum of squares per key from its pseudo-rows, ``|P [coef; -1]|^2``, where that is
        exact to ~1e-13: the cancellation in ``P`` costs ~eps |y| |r|, so every key's residual must
        keep at least ``min_share`` of its ``|y|^2``; None otherwise (a near-exact fit: the rows)."""
        if not self.key_pseudo or len(self.key_pseudo) != len(self.keys):
            return None
        x = np.append(coef, -1.0)
        sums = np.empty(len(self.keys))
        for i, P in enumerate(self.key_pseudo):
            r = P @ x
            sums[i] = r @ r
            if not sums[i] >= min_share * (P[:, -1] @ P[:, -1]):
                return None
        return sums

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
        for job in self.recording_jobs():
            yield job()

    def recording_jobs(self) -> Iterator[Callable[[], RecordingRows]]:
        """:meth:`recordings` as one callable per recording that forms its rows when called."""
        if self.store is None:
            raise RuntimeError("these regression data keep no rows")
        yield from self.store.free_jobs(self.free, self.theta_fixed, self.ties)


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
    stats = RowStatistics(len(theta_fixed))
    store = RowStore(budget=1 << 62)
    names: dict[str, int] = {}
    row_statistics(blocks, stats, store, names, offsets=offsets)
    return regression_data(stats, names, free, theta_fixed, store).stacked()
