"""Start-up of the commands as a user runs them (issue 28): each command, in a fresh interpreter, imports
only the heavy libraries its work needs. An import hook records, for the first import of each scipy
subpackage, pandas and matplotlib, whether agvdyn code asked for it (numba's own imports, e.g. of
scipy.linalg.cython_blas when it loads kernels, are numba's start-up, not ours, and are left out: the
commands load no numba when the ahead-of-time kernels are built, but a JIT fallback still may).

The default ``identify`` and ``inspect`` need none of them: numpy's LU solve for the triangular
factors (an ulp from scipy's solve_triangular), numpy's FFT in double precision for the correlation
time, and our own Student's t quantile for the intervals (tests/test_scipy_free_numerics.py);
``validate`` needs none, nor ``simulate`` (its log is written from numpy columns, tests/test_log_columns.py).
Only ``import scipy`` itself (its version, the key of the filter cache) is left. ``identify`` of a ROS 2 bag
imports no rosbags either (the storage files read by agvdyn.io._bag_storage, the messages decoded by
agvdyn.io._cdr); rosbags is probed for every command."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

#: run in the child: the CLI with an import hook; prints {module: agvdyn importer} of the heavy first imports
_PROBE = r"""
import json, sys, traceback
HEAVY = ("pandas", "matplotlib", "scipy.")
found = {}
class Hook:
    def find_spec(self, name, path=None, target=None):
        if name in found or not (name in ("pandas", "matplotlib", "rosbags") or
                                 (name.startswith("scipy.") and name.count(".") == 1 and not name.startswith("scipy._"))):
            return None
        stack = [f.filename for f in traceback.extract_stack()[:-1]]
        if any("/numba/" in f or f.endswith("scipy/__init__.py") for f in stack):
            return None  # numba's own start-up; scipy's own package (scipy.version: what the filter cache reads)
        ours = [f for f in stack if "/agvdyn/" in f]
        found[name] = ours[-1] if ours else "?"
        return None
sys.meta_path.insert(0, Hook())
sys.argv = ["agvdyn", *sys.argv[1:]]
from agvdyn.cli import main
code = 0
try:
    main()
except SystemExit as exc:
    code = exc.code or 0
print("IMPORTS " + json.dumps({"code": code, "found": {k: v for k, v in found.items() if v != "?"}}))
"""



def _heavy_imports(args: list[str], cwd: Path) -> dict[str, str]:
    out = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, timeout=120,
                         cwd=cwd)
    lines = [line for line in out.stdout.splitlines() if line.startswith("IMPORTS ")]
    assert lines, f"agvdyn {' '.join(args)} printed no report:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}"
    report = json.loads(lines[-1][len("IMPORTS "):])
    assert report["code"] == 0, f"agvdyn {' '.join(args)} failed:\n{out.stderr[-2000:]}"
    return report["found"]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    """A short identification run written by ``agvdyn simulate`` (itself probed) and its heavy imports."""
    folder = tmp_path_factory.mktemp("import_cost")
    found = _heavy_imports(["simulate", "identification", "--out", str(folder / "log.parquet"), "--quiet"], folder)
    return folder, found


def test_simulate_imports_neither_pandas_nor_scipy(simulated):
    _, found = simulated
    assert found == {}, f"simulate identification imported {found}"


def test_identify_imports_neither_pandas_nor_scipy(simulated):
    folder, _ = simulated
    found = _heavy_imports(["identify", "log.parquet", "--out", "p.yaml"], folder)
    assert found == {}, f"identify imported {found}"


def test_inspect_imports_neither_pandas_nor_scipy(simulated):
    folder, _ = simulated
    found = _heavy_imports(["inspect", "log.parquet"], folder)
    assert found == {}, f"inspect imported {found}"  # its trial fit (the relative stds) included


def test_validate_imports_neither_pandas_nor_scipy(simulated):
    folder, _ = simulated
    if not (folder / "p.yaml").exists():
        _heavy_imports(["identify", "log.parquet", "--out", "p.yaml"], folder)
    for args in (["validate", "log.parquet", "--params", "p.yaml"],
                 ["validate", "log.parquet", "--params", "p.yaml", "--json"]):
        found = _heavy_imports(args, folder)
        assert found == {}, f"agvdyn {' '.join(args)} imported {found}"


def test_identify_of_a_bag_imports_neither_rosbags_nor_pandas_nor_scipy(simulated):
    """An MCAP bag written by write_bag (rosbags' Writer) from the simulated log, identified through a mapping."""
    from agvdyn.io import read_log, read_mapping, write_bag
    from agvdyn.platform import PROTOTYPE

    folder, _ = simulated
    example = Path(__file__).resolve().parents[1] / "examples" / "mappings" / "ros2_control.yaml"
    mapping = folder / "bag.yaml"
    mapping.write_text(example.read_text() + f"\ni_G: {PROTOTYPE.i_G!r}\n")
    if not (folder / "bag").exists():
        write_bag(read_log(folder / "log.parquet"), folder / "bag", read_mapping(mapping), "mcap")
    found = _heavy_imports(["identify", "bag", "--mapping", str(mapping), "--out", "pb.yaml"], folder)
    assert found == {}, f"identify of a bag imported {found}"
