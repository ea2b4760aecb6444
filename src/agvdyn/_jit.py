"""The compiled kernels: numba's JIT, or the same kernels compiled ahead of time.

Every kernel module decorates with :func:`njit` from here instead of ``numba.njit``. When the
ahead-of-time module ``agvdyn._aot_kernels`` exists (``python -m agvdyn._aot_build``, run by
``make``) and was built from the kernel sources as they are now, a kernel is a :class:`Kernel`: a
call whose argument types are among the compiled signatures runs the compiled code without
importing numba (numba's per-process start, 0.3-0.4 s, issue 28); any other call compiles the
kernel with numba as before. Otherwise ``njit`` is ``numba.njit`` itself.

The numbers are the same bit for bit: numba compiles both from the same source with the same
options (no fast-math, no contraction of multiply-adds), for the host CPU (``AGVDYN_AOT_CPU`` at
build time for another model, ``generic`` for the architecture's generic one); the stamp holds the
CPU's model and flags, so that a module built on another CPU is not used. ``AGVDYN_JIT=1`` (or numba's own ``NUMBA_CPU_NAME`` /
``NUMBA_DISABLE_JIT``) forces numba's JIT for the process.
"""
from __future__ import annotations

import hashlib
import inspect
import json
import os
import sys
from pathlib import Path

import numpy as np

__all__ = ["njit", "Kernel", "aot_index", "cpu_fingerprint", "kernel_sources_stamp", "register_with_numba", "INDEX_FILE"]

PACKAGE = Path(__file__).resolve().parent
INDEX_FILE = PACKAGE / "_aot_kernels.json"
#: numpy scalar and Python types as the short codes of the index (numba's typing of a scalar argument)
_SCALAR_CODES = {float: "f8", int: "i8", bool: "b1"}


def cpu_fingerprint() -> str:
    """The host CPU's model and feature flags (Linux: /proc/cpuinfo), as text."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            lines = [line for line in f.read(65536).splitlines() if line.startswith(("model name", "flags"))]
        return "\n".join(lines[:2])
    except OSError:
        import platform

        return f"{platform.machine()} {platform.processor()}"


def kernel_sources_stamp(files: list[str]) -> str:
    """SHA-256 over the kernel source files (paths relative to the package), the versions whose ABI
    the compiled module depends on and the CPU it was compiled for (another CPU: numba's JIT)."""
    digest = hashlib.sha256(f"{sys.version_info[:2]} numpy {np.__version__}\n{cpu_fingerprint()}".encode())
    for name in files:
        digest.update(name.encode())
        digest.update((PACKAGE / name).read_bytes())
    return digest.hexdigest()


def _wants_jit() -> bool:
    env = os.environ
    return bool(env.get("AGVDYN_JIT") not in (None, "", "0") or env.get("NUMBA_CPU_NAME")
                or env.get("NUMBA_DISABLE_JIT") not in (None, "", "0"))


def _load_index() -> dict | None:
    """The index of the ahead-of-time module when it is present and current, else None."""
    if _wants_jit():
        return None
    try:
        index = json.loads(INDEX_FILE.read_text())
        if index["stamp"] != kernel_sources_stamp(index["files"]):
            return None
        from agvdyn import _aot_kernels  # noqa: PLC0415
    except (OSError, ValueError, KeyError, ImportError):
        return None
    index["module"] = _aot_kernels
    return index


_INDEX: dict | None | bool = False  # False: not loaded yet


def aot_index() -> dict | None:
    """The ahead-of-time index in use by this process (None: numba's JIT only)."""
    global _INDEX
    if _INDEX is False:
        _INDEX = _load_index()
    return _INDEX  # type: ignore[return-value]


def _type_code(value) -> str | None:
    """The index's code of an argument: ``f8:2C`` for a C-contiguous 2-D float64 array (``A``: any
    layout), ``i8`` for an int."""
    code = _SCALAR_CODES.get(type(value))
    if code is not None:
        return code
    if isinstance(value, np.ndarray):
        if value.dtype.byteorder == ">":
            return None
        return f"{value.dtype.kind}{value.dtype.itemsize}:{value.ndim}{'C' if value.flags.c_contiguous else 'A'}"
    if isinstance(value, np.generic):
        return f"{value.dtype.kind}{value.dtype.itemsize}"
    return None


class Kernel:
    """A kernel with ahead-of-time compiled signatures and numba's JIT for any other call."""

    def __init__(self, py_func, options: dict, compiled: list[tuple[tuple[str, ...], object]]):
        self.py_func = py_func
        self.options = options
        self._compiled = {codes: fn for codes, fn in compiled}
        self._nargs = len(inspect.signature(py_func).parameters)
        self._dispatcher = None
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__

    def __call__(self, *args, **kwargs):
        if not kwargs and len(args) == self._nargs:
            codes = tuple(_type_code(a) for a in args)
            fn = self._compiled.get(codes)
            if fn is None and None not in codes:  # the version for arrays of any layout
                fn = self._compiled.get(tuple(c[:-1] + "A" if c.endswith("C") else c for c in codes))
            if fn is not None:
                return fn(*args)
        return self.jit()(*args, **kwargs)

    def jit(self):
        """numba's dispatcher of this kernel (imports numba on first use)."""
        if self._dispatcher is None:
            register_with_numba()
            import numba

            self._dispatcher = numba.njit(**self.options)(self.py_func)
        return self._dispatcher

    def __repr__(self) -> str:
        return f"Kernel({self.__module__}.{self.__qualname__}, {len(self._compiled)} compiled signatures)"


_REGISTERED = False


def register_with_numba() -> None:
    """Let numba type a :class:`Kernel` met as a global inside another kernel as its dispatcher."""
    global _REGISTERED
    if _REGISTERED:
        return
    from numba.extending import typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(value, context):
        return typeof_impl(value.jit(), context)

    _REGISTERED = True


def njit(*args, **options):
    """``numba.njit`` with the same options; see the module's docstring."""
    if args and callable(args[0]):
        return njit(**options)(args[0])
    index = aot_index()
    if index is None:
        import numba

        return numba.njit(*args, **options)

    def decorate(py_func):
        name = f"{py_func.__module__}.{py_func.__qualname__}"
        entries = index["kernels"].get(name, [])
        module = index["module"]
        return Kernel(py_func, options, [(tuple(codes), getattr(module, symbol)) for codes, symbol in entries])

    return decorate
