"""The kernels compiled ahead of time (agvdyn._jit, agvdyn._aot_build): a command runs without
importing numba and gives numba's JIT results bit for bit; a call with other argument types, a kernel
used inside another numba function and a changed kernel source all fall back to numba."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numba
import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, strategies as hst

import agvdyn._jit as jit
from agvdyn._aot_build import _code

AOT = jit.aot_index() is not None
if not AOT and os.environ.get("AGVDYN_REQUIRE_AOT") == "1":
    raise RuntimeError("AGVDYN_REQUIRE_AOT=1 but agvdyn._aot_kernels is missing or stale: run "
                       "`.venv/bin/python -m agvdyn._aot_build` (make does)")
needs_aot = pytest.mark.skipif(not AOT, reason="agvdyn._aot_kernels not built (python -m agvdyn._aot_build)")

_RUN = ("import sys; from agvdyn.cli import app\n"
        "try:\n    app(sys.argv[1:])\nexcept SystemExit as e:\n    assert e.code in (0, None), e.code\n"
        "print('NUMBA', 'numba' in sys.modules)")


def _agvdyn(args: list[str], folder, jit_only: bool) -> bool:
    """Runs ``agvdyn ARGS`` in a fresh interpreter; returns whether it imported numba."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("AGVDYN_JIT", "NUMBA_"))}
    if jit_only:
        env["AGVDYN_JIT"] = "1"
    out = subprocess.run([sys.executable, "-c", _RUN, *args], cwd=folder, env=env, capture_output=True,
                         text=True, check=True).stdout
    return out.strip().splitlines()[-1] == "NUMBA True"


@needs_aot
def test_simulate_and_identify_run_without_numba_and_equal_the_jit(tmp_path):
    for mode, jit_only in (("aot", False), ("jit", True)):
        (tmp_path / mode).mkdir()
        for args in (["simulate", "identification", "--out", "log.parquet", "--seed", "3"],
                     ["identify", "log.parquet", "--out", "params.yaml"]):
            assert _agvdyn(args, tmp_path / mode, jit_only) == jit_only
    assert pq.read_table(tmp_path / "aot/log.parquet").equals(pq.read_table(tmp_path / "jit/log.parquet"))
    assert (tmp_path / "aot/params.yaml").read_text() == (tmp_path / "jit/params.yaml").read_text()


@needs_aot
def test_a_call_with_other_argument_types_runs_numba():
    from agvdyn._zero_phase import _odd_extension

    assert isinstance(_odd_extension, jit.Kernel)
    ext = np.arange(40.0, dtype=np.float32).reshape(20, 2) ** 1.5
    got, want = ext.copy(), ext.copy()
    _odd_extension(got, 12, 4)  # float32: not compiled ahead of time
    numba.njit(_odd_extension.py_func)(want, 12, 4)
    np.testing.assert_array_equal(got, want)
    assert got.dtype == np.float32


@needs_aot
def test_a_kernel_inside_another_numba_function_is_its_dispatcher():
    from agvdyn._trig import sincos_steering

    @numba.njit
    def both(x):
        return sincos_steering(x)

    assert both(0.3) == sincos_steering.jit()(0.3)


def test_an_index_of_other_sources_is_not_used(tmp_path, monkeypatch):
    index = {"stamp": "0" * 64, "files": ["_trig.py"], "kernels": {}}
    (tmp_path / "index.json").write_text(json.dumps(index))
    monkeypatch.setattr(jit, "INDEX_FILE", tmp_path / "index.json")
    monkeypatch.delenv("AGVDYN_JIT", raising=False)
    monkeypatch.delenv("NUMBA_CPU_NAME", raising=False)
    assert jit._load_index() is None
    if AOT:  # the same index with the stamp of the sources as they are: used
        index["stamp"] = jit.kernel_sources_stamp(index["files"])
        (tmp_path / "index.json").write_text(json.dumps(index))
        assert jit._load_index() is not None
    monkeypatch.setenv("AGVDYN_JIT", "1")
    assert jit._load_index() is None


_DTYPES = hst.sampled_from([np.float64, np.float32, np.int64, np.int32, np.int8, np.uint8, np.bool_])


@given(_DTYPES, hst.integers(0, 3))
def test_the_runtime_type_code_of_an_array_is_the_build_code_of_its_numba_type(dtype, ndim):
    value = np.zeros((2,) * ndim, dtype=dtype)[()] if ndim == 0 else np.zeros((2,) * ndim, dtype=dtype)
    assert jit._type_code(value) == _code(numba.typeof(value))
    if ndim == 2:  # a transposed or strided view: the code of any layout
        assert jit._type_code(value.T[::2]) == jit._type_code(value)[:-1] + "A" == _code(numba.typeof(value.T[::2]))


@given(hst.one_of(hst.floats(allow_nan=True), hst.integers(-2**62, 2**62), hst.booleans()))
def test_the_runtime_type_code_of_a_python_scalar_is_the_build_code_of_its_numba_type(value):
    assert jit._type_code(value) == _code(numba.typeof(value))
