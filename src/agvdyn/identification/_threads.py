"""Threads of the identification: how many by default, and an ordered map that keeps at most a few
items in flight (memory stays bounded however many logs or recordings there are)."""
from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
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
    ``workers + 1`` items taken ahead of the one yielded (one thread: plain ``map``). Twice as many
    ahead showed no speed-up on 25 logs and raised the peak of a 10 h log read in pieces from
    ~850 to 894 MB (the 1 GB bound)."""
    if workers <= 1:
        yield from map(fn, items)
        return
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix=name)
    try:
        pending: deque = deque()
        for item in items:
            pending.append(pool.submit(fn, item))
            if len(pending) > workers:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
