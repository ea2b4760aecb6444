"""Buffers reused from one log to the next: a fresh array of some megabytes costs a page fault per
4 kB page (measured: half of the row pipeline's time on a 35,500-sample log), a reused one none.

A :class:`Workspace` belongs to one thread and one identification; arrays taken from it are valid
until the same name is asked for again, so only callers that are done with a log's arrays before
the next log (``identify(..., keep_blocks=False)``) pass one.
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn._memory import keep_freed_memory  # re-exported

__all__ = ["Workspace", "empty", "keep_freed_memory"]


class Workspace:
    """Named buffers that grow to the largest size asked for and are handed out again as views."""

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}

    def empty(self, name: str, shape: tuple[int, ...], dtype: type | np.dtype = np.float64) -> np.ndarray:
        """An uninitialised array of ``shape`` and ``dtype`` in the buffer ``name``."""
        dtype = np.dtype(dtype)
        size = int(math.prod(shape)) * dtype.itemsize  # not np.prod: ~5 us a call, dozens of calls per log
        buffer = self._buffers.get(name)
        if buffer is None or buffer.nbytes < size:
            buffer = np.empty(max(size, 1), dtype=np.uint8)
            self._buffers[name] = buffer
        return buffer[:size].view(dtype).reshape(shape)


def empty(workspace: Workspace | None, name: str, shape: tuple[int, ...],
          dtype: type | np.dtype = np.float64) -> np.ndarray:
    """``workspace.empty(name, shape, dtype)``, or a fresh ``np.empty`` without a workspace."""
    return np.empty(shape, dtype) if workspace is None else workspace.empty(name, shape, dtype)
