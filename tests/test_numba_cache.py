"""numba's cache is keyed on the kernel's own file only: a module whose kernels call into another
file drops its cache when that file is newer (agvdyn._numba_cache)."""
from __future__ import annotations

import os

from agvdyn._numba_cache import drop_stale_cache


def _tree(tmp_path):
    module, callee = tmp_path / "kern.py", tmp_path / "callee.py"
    module.write_text("x = 1\n")
    callee.write_text("y = 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    files = [cache / "kern.run-12.py311.nbi", cache / "kern.run-12.py311.1.nbc", cache / "other.f-3.py311.nbi"]
    for f in files:
        f.write_bytes(b"")
    return module, callee, files


def test_cache_dropped_when_a_callee_is_newer(tmp_path):
    module, callee, (index, data, other) = _tree(tmp_path)
    os.utime(index, (1000, 1000))
    os.utime(callee, (2000, 2000))
    drop_stale_cache(str(module), str(callee))
    assert not index.exists() and not data.exists() and other.exists()  # only this module's kernels


def test_cache_kept_when_the_callees_are_older(tmp_path):
    module, callee, (index, data, other) = _tree(tmp_path)
    os.utime(callee, (1000, 1000))
    os.utime(index, (2000, 2000))
    drop_stale_cache(str(module), str(callee))
    assert index.exists() and data.exists()
    drop_stale_cache(str(module), str(tmp_path / "missing.py"))  # a vanished file: nothing happens
    assert index.exists()
