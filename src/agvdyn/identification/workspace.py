"""Buffers reused from one log to the next: a fresh array of some megabytes costs a page fault per
4 kB page (measured: half of the row pipeline's time on a 35,500-sample log), a reused one none.

A :class:`Workspace` belongs to one thread and one identification; arrays taken from it are valid
until the same name is asked for again, so only callers that are done with a log's arrays before
the next log (``identify(..., keep_blocks=False)``) pass one.
"""
from __future__ import annotations

import numpy as np

__all__ = ["Workspace", "empty", "keep_freed_memory"]

_KEPT = False


def keep_freed_memory() -> bool:
    """Ask glibc, once per process, to serve arrays below 64 MB from its heap and keep up to 64 MB
    of freed memory per arena for reuse (the command line keeps 256 MB), instead of fresh
    zero pages from the kernel for every temporary array of numpy, pandas and pyarrow: page faults
    cost half of the row pipeline's time on this project's machines, and they serialise threads
    (measured: 21.8 -> 13.5 ms per 35,500-sample log, two threads 0.7x -> 1.5x). MALLOC_* settings
    in the environment win; elsewhere than Linux/glibc nothing happens. Returns whether it was set."""
    global _KEPT
    if _KEPT:
        return True
    import ctypes
    import os
    import sys

    if not sys.platform.startswith("linux") or any(k.startswith("MALLOC_") for k in os.environ):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        for option, value in ((-3, 64 << 20), (-1, 64 << 20), (-2, 16 << 20)):  # M_MMAP_THRESHOLD, M_TRIM_THRESHOLD, M_TOP_PAD
            libc.mallopt(option, value)
    except (OSError, AttributeError):
        return False
    _KEPT = True
    return True


class Workspace:
    """Named buffers that grow to the largest size asked for and are handed out again as views."""

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}

    def empty(self, name: str, shape: tuple[int, ...], dtype: type | np.dtype = np.float64) -> np.ndarray:
        """An uninitialised array of ``shape`` and ``dtype`` in the buffer ``name``."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape)) * dtype.itemsize
        buffer = self._buffers.get(name)
        if buffer is None or buffer.nbytes < size:
            buffer = np.empty(max(size, 1), dtype=np.uint8)
            self._buffers[name] = buffer
        return buffer[:size].view(dtype).reshape(shape)


def empty(workspace: Workspace | None, name: str, shape: tuple[int, ...],
          dtype: type | np.dtype = np.float64) -> np.ndarray:
    """``workspace.empty(name, shape, dtype)``, or a fresh ``np.empty`` without a workspace."""
    return np.empty(shape, dtype) if workspace is None else workspace.empty(name, shape, dtype)
