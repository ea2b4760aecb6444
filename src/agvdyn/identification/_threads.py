"""Threads of the identification: how many by default, and an ordered map that keeps at most a few
items in flight (memory stays bounded however many logs or recordings there are)."""
from __future__ import annotations

import os
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor, wait
from typing import TypeVar

__all__ = ["default_workers", "ordered_map"]

T = TypeVar("T")
R = TypeVar("R")


def default_workers() -> int:
    """Threads that read and reduce logs at once by default: the cores this process may use, at
    most 2 (the compiled kernels, pyarrow, LAPACK and BLAS release the GIL). Measured on 25 logs of
    35,500 samples on an idle 2-core machine: 2 threads 1.3-1.6x one (docs/identification.md,
    "Speed"), for ~40 MB more; on a long log read in pieces each thread's buffers cost 120-170 MB
    (10 h log: 674 MB on one thread, 842 MB on two), so more threads by default would break the
    1 GB bound. The environment variable ``AGVDYN_THREADS`` overrides it."""
    env = os.environ.get("AGVDYN_THREADS", "").strip()
    if env:
        if not env.isdigit() or int(env) < 1:
            raise ValueError(f"AGVDYN_THREADS={env!r}: expected an integer >= 1")
        return int(env)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(2, cores))


def ordered_map(fn: Callable[[T], R], items: Iterable[T], workers: int, name: str = "agvdyn") -> Iterator[R]:
    """``map(fn, items)`` in up to ``workers`` threads, results in the items' order, at most
    ``workers + 1`` items taken ahead of the one yielded (one thread, or a call from inside one of
    these threads: plain ``map``). Twice as many ahead showed no speed-up on 25 logs and raised the
    peak of a 10 h log read in pieces from ~850 to 894 MB (the 1 GB bound). The threads are kept
    for the next call (:func:`_pool`). ``name``: the threads' name while they run ``fn``."""
    if workers <= 1 or getattr(_inside, "pool", False):
        yield from map(fn, items)
        return

    def named(item: T) -> R:
        thread = threading.current_thread()
        thread.name = name
        try:
            return fn(item)
        finally:
            thread.name = "agvdyn-idle"

    pool = _pool(workers)
    pending: deque = deque()
    try:
        for item in items:
            pending.append(pool.submit(named, item))
            if len(pending) > workers:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:
        for future in pending:  # stopped early (an error, or the caller closed the generator)
            future.cancel()
        wait(pending)


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()
_inside = threading.local()


def _pool(workers: int) -> ThreadPoolExecutor:
    """The process's pool of ``workers`` threads, started on first use and kept: starting threads
    took 2-3 ms each on the project's VM, and an identification maps three times (logs, correlation
    time, jackknife). Calls in parallel share it (each keeps its own bound on the items ahead)."""
    with _POOLS_LOCK:
        pool = _POOLS.get(workers)
        if pool is None:
            pool = _POOLS[workers] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="agvdyn-idle",
                                                        initializer=_mark_inside)
        return pool


def _mark_inside() -> None:
    _inside.pool = True  # a job that maps again runs that map itself (no deadlock on a full pool)


def _forget_pools() -> None:
    """In a forked child the parent's threads do not exist: start new pools there."""
    global _POOLS_LOCK
    _POOLS.clear()
    _POOLS_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)
