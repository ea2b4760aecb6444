"""Command-line interface: parses arguments and calls the library; no numerics here."""
from __future__ import annotations

from agvdyn.cli._app import app

# Each command module registers itself on ``app`` when imported.
from agvdyn.cli import model_commands  # noqa: E402,F401
from agvdyn.cli import io_commands  # noqa: E402,F401
from agvdyn.cli import identify_commands  # noqa: E402,F401
from agvdyn.cli import sim_commands  # noqa: E402,F401
from agvdyn.cli import inspect_command  # noqa: E402,F401
from agvdyn.cli import study_commands  # noqa: E402,F401
from agvdyn.cli import batch_commands  # noqa: E402,F401
from agvdyn.cli import plan_commands  # noqa: E402,F401


def _keep_freed_memory() -> None:
    """glibc: serve arrays below 64 MB from the heap and keep up to 256 MB of freed memory for reuse,
    instead of fresh zero pages from the kernel for every temporary array (page faults cost ~20 % of
    an identification). Set before anything is allocated; the environment's MALLOC_* settings win."""
    import ctypes
    import os
    import sys

    if not sys.platform.startswith("linux") or any(k.startswith("MALLOC_") for k in os.environ):
        return
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return
    for option, value in ((-3, 64 << 20), (-1, 256 << 20), (-2, 64 << 20)):  # M_MMAP_THRESHOLD, M_TRIM_THRESHOLD, M_TOP_PAD
        libc.mallopt(option, value)


def main() -> None:
    _keep_freed_memory()
    app()
