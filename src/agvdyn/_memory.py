"""glibc's reuse of freed memory (a light module: the command line sets it before anything loads)."""
from __future__ import annotations

__all__ = ["keep_freed_memory"]

_KEPT = False


def keep_freed_memory(trim: int = 64 << 20, top_pad: int = 16 << 20) -> bool:
    """Ask glibc, once per process (the first call wins), to serve arrays below 64 MB from its heap
    and keep up to ``trim`` bytes of freed memory per arena for reuse, instead of fresh zero pages
    from the kernel for every temporary array of numpy, pandas and pyarrow: page faults cost half of
    the row pipeline's time on this project's machines, and they serialise threads (measured: 21.8
    -> 13.5 ms per 35,500-sample log, two threads 0.7x -> 1.5x). pyarrow then allocates from
    glibc too (:func:`_arrow_from_glibc`). MALLOC_* settings in the environment win; elsewhere
    than Linux/glibc nothing happens. Returns whether it is set."""
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
        # M_MMAP_THRESHOLD, M_TRIM_THRESHOLD, M_TOP_PAD, M_ARENA_MAX (one arena: a thread's freed
        # memory serves the others instead of each keeping its own ``trim``; 25 logs in two threads
        # peaked at 567 MB with an arena per thread, 465 MB with one, at the same speed)
        for option, value in ((-3, 64 << 20), (-1, trim), (-2, top_pad), (-8, 1)):
            libc.mallopt(option, value)
    except (OSError, AttributeError):
        return False
    _arrow_from_glibc()
    _KEPT = True
    return True


def _arrow_from_glibc() -> None:
    """pyarrow allocates from glibc (its ``system`` pool) so that a read log's freed buffers serve
    the next log's read: with mimalloc, pyarrow's default, reading a 35,500-sample log took 3.6-4.4
    ms against 2.7-3.5 (25 logs read in turn). ARROW_DEFAULT_MEMORY_POOL in the environment wins."""
    import os
    import sys

    if "ARROW_DEFAULT_MEMORY_POOL" in os.environ:
        return
    if "pyarrow" not in sys.modules:
        os.environ["ARROW_DEFAULT_MEMORY_POOL"] = "system"  # read when pyarrow loads
        return
    import pyarrow

    pyarrow.set_memory_pool(pyarrow.system_memory_pool())
