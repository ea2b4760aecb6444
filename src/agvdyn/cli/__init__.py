"""Command-line interface: parses arguments and calls the library; no numerics here."""
from __future__ import annotations

from agvdyn.cli._app import app

# Each command module registers itself on ``app`` when imported.
from agvdyn.cli import model_commands  # noqa: E402,F401
from agvdyn.cli import io_commands  # noqa: E402,F401
from agvdyn.cli import identify_commands  # noqa: E402,F401
from agvdyn.cli import report_commands  # noqa: E402,F401
from agvdyn.cli import sim_commands  # noqa: E402,F401
from agvdyn.cli import inspect_command  # noqa: E402,F401
from agvdyn.cli import study_commands  # noqa: E402,F401
from agvdyn.cli import batch_commands  # noqa: E402,F401
from agvdyn.cli import plan_commands  # noqa: E402,F401
from agvdyn.cli import export_commands  # noqa: E402,F401
from agvdyn.cli import track_commands  # noqa: E402,F401


def one_blas_thread() -> None:
    """One BLAS thread per command unless the environment says otherwise; before numpy is imported
    (the commands import it lazily). The commands parallelise over logs themselves (``--workers``),
    and OpenBLAS' own threads busy-wait on a loaded host (a ROS stack, a shared machine): one-log
    identify 0.73 -> 0.45 s, 25 logs 2.3-5.9 -> 1.04 s at load average 4.5 on 2 cores; the sums are
    then also the same on any core count."""
    import os

    for var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # numpy's BLAS (pip wheels: OpenBLAS; conda: MKL)
        os.environ.setdefault(var, "1")


def main() -> None:
    one_blas_thread()
    from agvdyn._memory import keep_freed_memory

    keep_freed_memory(trim=256 << 20, top_pad=64 << 20)  # before anything is allocated; the library's call then keeps it
    if not _console_script():
        app()
        return
    try:
        app()
    except SystemExit as exc:
        _exit_without_teardown(exc.code)
    _exit_without_teardown(0)


def _console_script() -> bool:
    """Whether this process is the ``agvdyn`` command itself (the installed script), not a program
    or test that calls :func:`main` and goes on afterwards."""
    import os
    import sys

    script = getattr(sys.modules.get("__main__"), "__file__", None) or ""
    return os.path.basename(script).removesuffix(".exe") == "agvdyn"


def _exit_without_teardown(code: object) -> None:
    """End the command as Python's exit does (threads joined, ``atexit`` handlers run: temporary
    folders removed, logs flushed; the exit status of ``SystemExit(code)``), but without tearing
    down the interpreter: freeing numba's typing registries and every module object took
    0.25-0.34 s after each command (issue 28), for nothing the operating system does not do."""
    import atexit
    import os
    import sys
    import threading

    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:  # SystemExit("message"): printed, status 1
        print(code, file=sys.stderr)
        status = 1
    threading._shutdown()  # noqa: SLF001 - what the interpreter runs first at exit: wait for non-daemon threads
    atexit._run_exitfuncs()  # noqa: SLF001
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be written
            pass
    os._exit(status & 0xFF)  # as the interpreter: sys.exit(-1) is status 255
