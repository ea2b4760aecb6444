"""Logs at the boundary: :func:`load_logs` (every log in memory, for commands that need the whole
log: ``inspect``, ``report``, ``validate``) and :func:`open_logs` (files read when used, a long log in
our schema a piece at a time: ``identify``, whose memory does not grow with the logs' number or
length). Both check the inputs and read the mapping and platform files once; the identification
takes what they return and does no file I/O of its own.
"""
from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from agvdyn.io.load import load_log
from agvdyn.io.log import STOP_TOLERANCE, Log, LogError
from agvdyn.io.mapping import LogMapping
from agvdyn.platform import Geometry, read_platform

__all__ = ["LogFile", "open_logs", "load_logs", "log_pieces_of"]

PathLike = str | os.PathLike


class LogFile:
    """A log file checked at the boundary and read when it is used: whole (:func:`load_log`), or,
    a long log in our schema (:func:`agvdyn.io.chunks.is_long_log`), a piece at a time with its
    neighbours' overlap (:func:`agvdyn.io.chunks.log_pieces`).

    :meth:`first` reads the first piece (or the whole log) once for a look at the labels and the
    sidecar; the next :meth:`pieces` starts with it and does not read it again.
    """

    def __init__(self, path: PathLike, mapping: LogMapping | None = None, platform: Geometry | None = None,
                 stop_tolerance: float = STOP_TOLERANCE) -> None:
        self.path, self.mapping, self.platform = Path(path), mapping, platform
        self.stop_tolerance = float(stop_tolerance)
        self._head: tuple[tuple[Log, slice | None], Iterator[tuple[Log, slice | None]]] | None = None

    def __repr__(self) -> str:
        return f"LogFile({str(self.path)!r})"

    @property
    def long(self) -> bool:
        """Read in pieces: a long log in our schema (never a mapped table or a bag)."""
        from agvdyn.io.chunks import is_long_log

        return self.mapping is None and is_long_log(self.path)

    def _read(self) -> Iterator[tuple[Log, slice | None]]:
        if self.long:
            from agvdyn.io.chunks import log_pieces

            yield from log_pieces(self.path, stop_tolerance=self.stop_tolerance)
        else:
            yield self.load(), None

    def load(self) -> Log:
        """The whole log (the one :meth:`first` read, when it read the whole log)."""
        if self._head is not None and self._head[0][1] is None:
            (log, _), self._head = self._head[0], None
            return log
        return load_log(self.path, self.mapping, self.platform, stop_tolerance=self.stop_tolerance)

    def first(self) -> Log:
        """The first piece, or the whole log when it is not read in pieces (kept for :meth:`pieces`)."""
        if self._head is None:
            pieces = self._read()
            self._head = (next(pieces), pieces)
        return self._head[0][0]

    def head(self) -> Log:
        """The first piece, or the whole log, read now and not kept (for a second look)."""
        if self._head is not None:
            return self._head[0][0]
        return next(iter(self._read()))[0]

    def pieces(self) -> Iterator[tuple[Log, slice | None]]:
        """``(log, core)`` of each piece in order (``core`` the piece's own rows), or ``(log, None)`` once."""
        if self._head is not None:
            (head, rest), self._head = self._head, None
            yield head
            yield from rest
            return
        yield from self._read()


def _mapping_and_platform(mapping: LogMapping | PathLike | None, platform: Geometry | PathLike | None
                          ) -> tuple[LogMapping | None, Geometry | None]:
    if mapping is not None and not isinstance(mapping, LogMapping):
        from agvdyn.io.mapping_file import read_mapping

        mapping = read_mapping(mapping)
    if platform is not None and not isinstance(platform, Geometry):
        platform = read_platform(platform)
    return mapping, platform


def _items(logs: Any) -> list[Any]:
    items = [logs] if isinstance(logs, (str, os.PathLike, Log)) else list(logs)
    if not items:
        raise ValueError("no logs given: expected at least one log")
    return items


def open_logs(paths: PathLike | Sequence[PathLike], *, mapping: LogMapping | PathLike | None = None,
              platform: Geometry | PathLike | None = None, stop_tolerance: float | None = None) -> list[LogFile]:
    """Log files to be read when used (:class:`LogFile`); a missing file is an error now."""
    mapping, platform = _mapping_and_platform(mapping, platform)
    tol = STOP_TOLERANCE if stop_tolerance is None else stop_tolerance
    out = []
    for path in _items(paths):
        if not Path(path).exists():
            raise LogError(f"{path}: no such file or directory")
        out.append(LogFile(path, mapping, platform, tol))
    return out


def load_logs(logs: Any, *, mapping: LogMapping | PathLike | None = None, platform: Geometry | PathLike | None = None,
              stop_tolerance: float | None = None) -> list[Log]:
    """Logs as :class:`Log` objects in memory: paths are loaded and checked with
    ``load_log(path, mapping, platform)`` (mapping: for tables and bags not in our schema), Log
    objects are passed through."""
    items = _items(logs)
    tol = STOP_TOLERANCE if stop_tolerance is None else stop_tolerance
    if any(isinstance(x, (str, os.PathLike)) for x in items):
        mapping, platform = _mapping_and_platform(mapping, platform)
    return [load_log(x, mapping, platform, stop_tolerance=tol) if isinstance(x, (str, os.PathLike)) else x
            for x in items]


def log_pieces_of(log: Log | LogFile) -> Iterator[tuple[Log, slice | None]]:
    """``(log, core)`` of a log in memory (itself, None) or of a :class:`LogFile` (its pieces)."""
    if isinstance(log, LogFile):
        yield from log.pieces()
    else:
        yield log, None
