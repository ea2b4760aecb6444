"""The row store of an identification: the kept rows of every continuous recording, in memory up
to a budget and then in plain ``.npy`` files of a temporary folder (memory-mapped when read
back), for the covariances that need single rows (:mod:`.uncertainty`), eq. (25)'s sigma^2 and
the residual RMS. Rows are kept as one ``[A | y]`` block per recording as they come from
:func:`.normal.reduce_blocks` (no copy), A's columns optionally with the free ones first so that
the regression reads them as a view (:meth:`RowStore.free_rows`)."""
from __future__ import annotations

import functools
import shutil
import tempfile
import weakref
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["RecordingRows", "RowStore"]


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

    def __init__(self, budget: int = 128 << 20, columns: Sequence[int] | None = None) -> None:
        self.budget = budget
        #: natural column of each stored column of A (None: as given); see :meth:`free_rows`
        self.columns = None if columns is None else np.asarray(columns, dtype=np.int64)
        self._items: list[_Packed | tuple[Path, Path]] = []
        self._bytes = 0
        self._folder: Path | None = None
        self._cleanup: weakref.finalize | None = None
        self._keys = True
        self._spans: list[int] = []
        self._rows: list[int] = []

    def add(self, rows: RecordingRows) -> None:
        A = rows.A if self.columns is None else rows.A[:, self.columns]
        self.add_packed(np.column_stack([A, rows.y]), rows.group, rows.step, rows.key)

    def add_packed(self, rows: np.ndarray, group: np.ndarray, step: np.ndarray, key: np.ndarray | None) -> None:
        """Rows ``[A | y]`` (m, w + 1) of one recording (A's columns in the order of ``columns``)
        with their coordinate codes, steps and keys."""
        self._keys = self._keys and key is not None
        self._spans.append(int(step.max() - step.min()) + 1 if step.size else 0)
        self._rows.append(int(rows.shape[0]))
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
            if isinstance(item, tuple):  # the rows mapped, read from the page cache only where used
                rows, codes = np.load(item[0], mmap_mode="r"), np.load(item[1])
                key = codes[:, 2].astype(np.int16)
                yield _Packed(rows, codes[:, 0].astype(np.int8), codes[:, 1],
                              None if key.size and key[0] < 0 else key)
            else:
                yield item

    def __iter__(self) -> Iterator[RecordingRows]:
        """Rows of each recording with A's columns in their natural order (when the store holds them
        in another, A is reordered on first use: asking for ``step`` alone costs no copy)."""
        inverse = None if self.columns is None else np.argsort(self.columns)
        for p in self.packed():
            if inverse is None:
                yield RecordingRows(p.rows[:, :-1], p.rows[:, -1], p.group, p.step, p.key)
                continue
            rec = _ReorderedRows(None, p.rows[:, -1], p.group, p.step, p.key)  # type: ignore[arg-type]
            object.__setattr__(rec, "_source", (p.rows, inverse))
            yield rec

    def free_rows(self, free: Sequence[int], theta_fixed: np.ndarray) -> Iterator[RecordingRows]:
        """Rows of each recording with the columns ``free`` only and ``y - A theta_fixed`` (eq. 24);
        A a view of the stored rows when they hold the free columns first, in this order."""
        for job in self.free_jobs(free, theta_fixed):
            yield job()

    def free_jobs(self, free: Sequence[int], theta_fixed: np.ndarray,
                  ties: Sequence[tuple[int, int]] = ()) -> Iterator[Callable[[], RecordingRows]]:
        """:meth:`free_rows` as one callable per recording that forms its rows when called (in a
        worker thread, say); the recordings are only referenced here. ``ties``: (column, free column)
        pairs, natural indices: the first column's values added to the second's (one parameter for both)."""
        free = list(free)
        if ties:
            return self._tied_jobs(free, theta_fixed, ties)
        w = len(theta_fixed)
        stored = np.arange(w) if self.columns is None else self.columns
        first = list(stored[:len(free)]) == free
        held = [i for i in range(w) if theta_fixed[stored[i]] != 0.0]
        values = theta_fixed[stored[held]]
        where = np.argsort(stored)[free] if not first else None

        def rows_of(p: _Packed) -> RecordingRows:
            y = p.rows[:, -1]
            if len(held) == 1:  # B_w alone (the default): one column, no copy of it
                y = y - p.rows[:, held[0]] * values[0]
            elif held:
                y = y - p.rows[:, held] @ values
            A = p.rows[:, :len(free)] if first else p.rows[:, where]
            return RecordingRows(A, y, p.group, p.step, p.key)

        return (functools.partial(rows_of, p) for p in self.packed())

    def _tied_jobs(self, free: list[int], theta_fixed: np.ndarray, ties: Sequence[tuple[int, int]]
                   ) -> Iterator[Callable[[], RecordingRows]]:
        """:meth:`free_jobs` with tied columns: the free rows (a copy), each tie's column added to its free column."""
        position = np.argsort(np.arange(len(theta_fixed)) if self.columns is None else self.columns)

        def rows_of(job: functools.partial) -> RecordingRows:
            rec, p = job(), job.args[0]
            A = np.array(rec.A, dtype=float)
            for column, target in ties:
                A[:, free.index(target)] += p.rows[:, position[column]]
            return RecordingRows(A, rec.y, rec.group, rec.step, rec.key)

        return (functools.partial(rows_of, job) for job in self.free_jobs(free, theta_fixed))

    def row_counts(self) -> list[int]:
        """Rows of each recording, without reading them back."""
        return list(self._rows)

    def lengths(self) -> list[int]:
        """Steps each recording spans (last minus first step plus one), without reading rows back."""
        return list(self._spans)

    @property
    def keys(self) -> bool:
        """Every recording carries the (segment, coordinate) key of its rows."""
        return self._keys and bool(self._items)

    def __len__(self) -> int:
        return len(self._items)

    @property
    def spilled(self) -> int:
        return sum(isinstance(i, tuple) for i in self._items)

    def close(self) -> None:
        if self._cleanup is not None:
            self._cleanup()
        self._items.clear()


class _ReorderedRows(RecordingRows):
    """:class:`RecordingRows` whose A is taken from the stored rows (columns reordered) on first use."""

    def __getattribute__(self, name: str):
        value = object.__getattribute__(self, name)
        if name == "A" and value is None:
            rows, inverse = object.__getattribute__(self, "_source")
            value = rows[:, inverse]
            object.__setattr__(self, "A", value)
        return value


@dataclass(frozen=True, eq=False)
class _Packed:
    rows: np.ndarray
    group: np.ndarray
    step: np.ndarray
    key: np.ndarray | None
