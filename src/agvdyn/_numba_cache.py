"""numba's on-disk cache (``cache=True``) is invalidated only when the file of the cached function
changes, not when a compiled function it calls in another file does. A module whose kernels call
into other files calls :func:`drop_stale_cache` before defining them, so that an edit of a callee
recompiles its callers instead of running stale machine code."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["drop_stale_cache"]


def drop_stale_cache(module_file: str, *dependencies: str) -> None:
    """Remove the cached kernels of ``module_file`` (its ``__pycache__/<stem>.*.nbi|nbc``) when a
    file in ``dependencies`` is newer than the oldest cache index; unreadable or vanished files are
    ignored (another process may be doing the same)."""
    folder = Path(module_file).parent / "__pycache__"
    stem = Path(module_file).stem
    try:
        index = [p.stat().st_mtime for p in folder.glob(f"{stem}.*.nbi")]
        if not index or max(os.stat(d).st_mtime for d in dependencies) <= min(index):
            return
        for p in folder.glob(f"{stem}.*.nb[ic]"):
            p.unlink(missing_ok=True)
    except OSError:
        return
