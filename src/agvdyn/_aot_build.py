"""Build ``agvdyn._aot_kernels``: the kernels that the commands call, compiled ahead of time by numba
(``numba.pycc``) so that a command does not import numba (see :mod:`agvdyn._jit`).

    python -m agvdyn._aot_build [--quiet]

It runs a workload of commands under numba's JIT (``AGVDYN_JIT=1``) to learn the argument types
each kernel is called with, compiles each kernel for those types (arrays of any layout) with the
options of its decorator, and writes the module and its index ``_aot_kernels.json`` (the stamp of
the kernel sources it was built from) into the package. A call with other types, or any call after
a kernel source changed, runs numba's JIT as before. ``make`` runs this after installing.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ["AGVDYN_JIT"] = "1"  # before agvdyn is imported: every kernel a numba dispatcher

MODULE = "_aot_kernels"
#: commands whose kernels are compiled: the user paths of issue 28 and the golden set
WORKLOAD = (
    ("simulate", "identification", "--out", "{d}/ident.parquet", "--seed", "1"),
    ("simulate", "lane-change", "--out", "{d}/lane.parquet", "--seed", "2"),
    ("simulate", "car-like", "--out", "{d}/carlike.parquet", "--seed", "3"),
    ("simulate", "lifted-wheel", "--out", "{d}/lifted.parquet", "--seed", "4"),
    ("simulate", "identification", "--out", "{d}/slip.parquet", "--seed", "5", "--slip"),
    ("simulate", "identification", "--out", "{d}/ident.csv", "--seed", "6"),
    ("identify", "{d}/ident.parquet", "--out", "{d}/p.yaml"),
    ("identify", "{d}/ident.csv", "--out", "{d}/p_csv.yaml", "--estimator", "ols", "--uncertainty", "classic"),
    ("identify", "{d}/ident.parquet", "--out", "{d}/p_rob.yaml", "--estimator", "robust", "--uncertainty", "hac"),
    ("identify", "{d}/ident.parquet", "--out", "{d}/p_bnd.yaml", "--estimator", "bounded",
     "--uncertainty", "bootstrap"),
    ("identify", "{d}/slip.parquet", "--out", "{d}/p_slip.yaml"),
    ("identify", "{d}/ident.parquet", "{d}/carlike.parquet", "--fix", "none", "--out", "{d}/p_all.yaml"),
    ("identify", "{d}/lifted.parquet", "--out", "{d}/p_lifted.yaml"),
    ("identify", "{d}/lane.parquet", "--out", "{d}/p_lane.yaml"),
    ("inspect", "{d}/ident.parquet", "{d}/lane.parquet", "{d}/slip.parquet"),
    ("validate", "{d}/lane.parquet", "--params", "{d}/p.yaml"),
    ("track", "{d}/ident.parquet", "--params", "{d}/p.yaml", "--out", "{d}/t.parquet"),
    ("report", "--ident", "{d}/ident.parquet", "--validation", "{d}/lane.parquet", "--out", "{d}/r.html",
     "--params-out", "{d}/r.yaml"),
)


def run_workload(folder: str, progress) -> None:
    """The commands of :data:`WORKLOAD`, in this process, their output discarded."""
    from agvdyn.cli import app

    for command in WORKLOAD:
        argv = [a.format(d=folder) for a in command]
        progress(" ".join(argv[:2]))
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            try:
                app(argv, standalone_mode=False)
            except SystemExit as exc:
                if exc.code not in (0, None):
                    raise RuntimeError(f"workload command failed: agvdyn {' '.join(argv)}") from exc


def _code(t) -> str | None:
    """The index's code of a numba argument type (see ``agvdyn._jit._type_code``); None: not exported."""
    import numpy as np
    from numba.core import types

    if isinstance(t, types.Literal):
        return None
    if isinstance(t, types.Array):
        dtype = np.dtype(str(t.dtype))
        return f"{dtype.kind}{dtype.itemsize}:{t.ndim}{'C' if t.layout == 'C' else 'A'}"
    if isinstance(t, (types.Float, types.Integer, types.Boolean)):
        dtype = np.dtype(str(t)) if not isinstance(t, types.Boolean) else np.dtype(bool)
        return f"{dtype.kind}{dtype.itemsize}"
    return None


def _general(t, layout: str | None = None):
    """An array type of the layout of ``t`` (C-contiguous or any: ``layout="A"``), writable (an array
    that is not is passed the same way)."""
    from numba.core import types

    if isinstance(t, types.Array):
        return types.Array(t.dtype, t.ndim, layout or ("C" if t.layout == "C" else "A"), readonly=False,
                           aligned=True)
    return t


def harvested_kernels() -> dict:
    """``{qualified name: (dispatcher, [(codes, argument types)])}`` for every agvdyn kernel that the
    workload called, one entry per distinct list of argument codes."""
    from numba.core.registry import CPUDispatcher

    found: dict = {}
    for name, module in sorted(sys.modules.items()):
        if not name.startswith("agvdyn") or module is None:
            continue
        for value in vars(module).values():
            if not isinstance(value, CPUDispatcher) or value.__module__ != name:
                continue
            qual = f"{name}.{value.py_func.__qualname__}"
            entries = {}
            for args in value.signatures:  # as called (C-contiguous arrays: faster loops), and for any layout
                for layout in (None, "A"):
                    general = tuple(_general(t, layout) for t in args)
                    codes = tuple(_code(t) for t in general)
                    if None not in codes:
                        entries.setdefault(codes, general)
            if entries:
                found[qual] = (value, sorted(entries.items()))
    return found


def _kernel_sources(package: Path) -> list[str]:
    """The source files (relative to the package) of the loaded modules that define kernels: what
    the compiled kernels were built from, and all they can call."""
    files = set()
    for name, module in list(sys.modules.items()):
        path = getattr(module, "__file__", None) if name.startswith("agvdyn") else None
        if path and path.endswith(".py") and name not in ("agvdyn._jit", __name__, "__main__"):
            if "njit" in Path(path).read_text(encoding="utf-8"):
                files.add(str(Path(path).resolve().relative_to(package)))
    return sorted(files)


def _per_kernel_flags(options_of: dict) -> None:
    """Compile each exported kernel with its decorator's options (pycc uses one default set)."""
    import numba.pycc.compiler as pycc_compiler

    compile_extra = pycc_compiler.compile_extra

    def compile_with_options(typing_context, target_context, func, args, return_type, flags, locals, library):
        options = options_of.get(func, {})
        flags = flags.copy()
        flags.release_gil = bool(options.get("nogil", False))
        flags.error_model = options.get("error_model", "python")
        if options.get("fastmath"):
            raise ValueError(f"{func.__qualname__}: fast-math kernels are not compiled ahead of time")
        return compile_extra(typing_context, target_context, func, args, return_type, flags, locals, library)

    pycc_compiler.compile_extra = compile_with_options


def build(quiet: bool = False) -> Path:
    """Run the workload, compile the module and write it and its index into the package."""
    import json
    import shutil

    import agvdyn._jit as jit
    from numba.core import typing
    from numba.pycc import CC
    from numba.pycc.compiler import ExportEntry

    say = (lambda *_: None) if quiet else (lambda text: print(text, flush=True))
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="agvdyn-aot-") as folder:
        run_workload(folder, lambda what: say(f"  workload: agvdyn {what}"))
        kernels = harvested_kernels()
        cc = CC(MODULE)
        cc.output_dir = folder
        cpu = os.environ.get("AGVDYN_AOT_CPU", "host")
        cc.target_cpu = "" if cpu == "generic" else cpu  # "": numba's generic model of the architecture
        cc.verbose = False
        index, options_of = {}, {}
        for n, (qual, (dispatcher, entries)) in enumerate(sorted(kernels.items())):
            options_of[dispatcher.py_func] = dict(dispatcher.targetoptions)
            for k, (codes, args) in enumerate(entries):
                symbol = f"k{n}_{k}_{dispatcher.py_func.__name__}"
                cc._exported_functions[symbol] = ExportEntry(symbol, typing.signature(None, *args),
                                                             dispatcher.py_func)
                index.setdefault(qual, []).append([list(codes), symbol])
        _per_kernel_flags(options_of)
        say(f"  compiling {sum(len(v) for v in index.values())} signatures of {len(index)} kernels")
        cc.compile()
        built = next(Path(folder).glob(f"{MODULE}*.so"))
        files = _kernel_sources(jit.PACKAGE)
        target = jit.PACKAGE / built.name
        tmp = target.with_suffix(".tmp")
        shutil.copyfile(built, tmp)
        os.replace(tmp, target)
        text = json.dumps({"stamp": jit.kernel_sources_stamp(files), "files": files, "kernels": index}, indent=1)
        tmp_index = jit.INDEX_FILE.with_suffix(".tmp")
        tmp_index.write_text(text)
        os.replace(tmp_index, jit.INDEX_FILE)
    say(f"wrote {target.name} and {jit.INDEX_FILE.name} in {time.perf_counter() - start:.0f} s")
    return target


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quiet", action="store_true")
    build(parser.parse_args().quiet)


if __name__ == "__main__":
    main()
