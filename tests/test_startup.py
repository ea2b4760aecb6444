"""Start-up of the command line (issue 12): importing agvdyn.cli imports none of the heavy libraries, and
the literal option defaults of agvdyn.cli._defaults equal the library constants they stand for."""
from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("scipy", "numba", "matplotlib", "rosbags", "dask", "distributed", "pandas", "pyarrow",
         "agvdyn.identification", "agvdyn.simulation", "agvdyn.kinematics", "agvdyn.dynamics", "agvdyn.io",
         "agvdyn.report", "agvdyn.preflight", "agvdyn.montecarlo", "agvdyn.batch")


def _loaded_after(code: str) -> list[str]:
    probe = (f"import sys\n{code}\nimport json\n"
             f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_importing_the_cli_loads_no_heavy_module():
    assert _loaded_after("import agvdyn.cli") == []


def test_building_the_help_loads_no_heavy_module():
    # typer resolves every option declaration when it builds the command group and its help
    code = ("import typer.main, agvdyn.cli\n"
            "group = typer.main.get_command(agvdyn.cli.app)\n"
            "ctx = group.make_context('agvdyn', ['--help'], resilient_parsing=True)\n"
            "group.get_help(ctx)\n"
            "for name in group.list_commands(ctx):\n"
            "    cmd = group.get_command(ctx, name)\n"
            "    cmd.get_help(cmd.make_context(name, [], parent=ctx, resilient_parsing=True))")
    assert _loaded_after(code) == []


def test_version_answers_without_the_library():
    out = subprocess.run([sys.executable, "-c", "from agvdyn.cli import main; main()", "--version"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("agvdyn ")


def test_literal_defaults_equal_the_library_constants():
    from agvdyn.cli import _defaults
    from agvdyn.identifiability import QR_TOLERANCE
    from agvdyn.identification import IdentificationSettings
    from agvdyn.identification.estimators import ESTIMATORS
    from agvdyn.io import STOP_TOLERANCE
    from agvdyn.kinematics import MODE_TOLERANCE

    assert _defaults.QR_TOLERANCE == QR_TOLERANCE
    assert _defaults.STOP_TOLERANCE == STOP_TOLERANCE
    assert _defaults.MODE_TOLERANCE == MODE_TOLERANCE
    assert _defaults.ESTIMATORS == tuple(ESTIMATORS)
    assert _defaults.UNCERTAINTY == IdentificationSettings().uncertainty.method.value


def test_package_names_are_still_there():
    import agvdyn
    from agvdyn import PARAMETER_NAMES, PROTOTYPE
    from agvdyn.platform import PROTOTYPE as prototype

    assert PROTOTYPE is prototype and agvdyn.Geometry is type(prototype)
    assert len(PARAMETER_NAMES) == 11


def _arrow_pool_after(code: str, env: dict[str, str]) -> str:
    import os

    probe = f"{code}\nimport pyarrow\nprint(pyarrow.default_memory_pool().backend_name)"
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("MALLOC_", "ARROW_DEFAULT_MEMORY_POOL"))}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True,
                         env={**clean, **env})
    return out.stdout.strip().splitlines()[-1]


def test_kept_freed_memory_serves_pyarrow_from_glibc_unless_told_otherwise():
    if not sys.platform.startswith("linux"):
        return
    keep = "from agvdyn._memory import keep_freed_memory\nassert keep_freed_memory()"
    assert _arrow_pool_after(keep, {}) == "system"  # before pyarrow loads: by the environment
    assert _arrow_pool_after("import pyarrow\n" + keep, {}) == "system"  # after: set on the loaded module
    assert _arrow_pool_after(keep, {"ARROW_DEFAULT_MEMORY_POOL": "mimalloc"}) == "mimalloc"
    assert _arrow_pool_after("from agvdyn._memory import keep_freed_memory\nassert not keep_freed_memory()",
                             {"MALLOC_ARENA_MAX": "2"}) != "system"


# Issue 28: each command imports what it uses, no more.

def test_importing_the_cli_reads_no_distribution_metadata():
    # __version__ is looked up when asked for (importlib.metadata: 40-90 ms of every command)
    probe = "import sys, agvdyn.cli\nprint('importlib.metadata' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "False"
    import agvdyn

    assert agvdyn.__version__ and isinstance(agvdyn.__version__, str)


def test_simulating_a_built_in_experiment_needs_no_scipy_optimize_or_interpolate():
    # scipy.optimize (the lane change's amplitude) and scipy.interpolate (trajectory files) were ~0.4 s of
    # every simulate's start-up
    code = ("from agvdyn.trajectories import experiment\n"
            "import agvdyn.simulation\n"
            "experiment('identification')")
    probe = (f"import json, sys\n{code}\n"
             "print(json.dumps([m for m in ('scipy.optimize', 'scipy.interpolate') if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_inspect_and_identify_of_a_pandas_written_log_import_no_pandas_or_matplotlib(tmp_path):
    import numpy as np
    import pandas as pd

    rng = np.random.default_rng(0)
    n = 5000
    t = np.arange(n) * 0.002
    frame = pd.DataFrame({"t": t, "alpha_l": 0.3 * np.sin(t), "alpha_r": 0.2 * np.sin(t)})
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        frame[f"beta_{w}"] = t * (k + 1)
        frame[f"m_{w}"] = rng.normal(size=n).astype(np.float32)
    frame["segment"] = np.where(t < 5, "steer_left", None)
    frame.to_parquet(tmp_path / "log.parquet")  # as another tool writes it: strings, float32 torques
    code = ("import sys\nfrom agvdyn.cli import main\n"
            f"sys.argv = ['agvdyn', 'inspect', {str(tmp_path / 'log.parquet')!r}]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print('LOADED', [m for m in ('pandas', 'matplotlib') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    loaded = [line for line in out.stdout.splitlines() if line.startswith("LOADED")]
    assert loaded == ["LOADED []"], out.stdout + out.stderr


def test_the_installed_command_exits_with_its_status_and_all_output(tmp_path):
    # agvdyn.cli.main ends the console script without tearing the interpreter down (0.25-0.34 s saved)
    from pathlib import Path

    exe = Path(sys.executable).with_name("agvdyn")
    if not exe.exists():
        return
    out = subprocess.run([str(exe), "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.startswith("agvdyn ")
    out = subprocess.run([str(exe), "identify", str(tmp_path / "missing.parquet"), "--out", str(tmp_path / "p.yaml")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "no such file" in out.stderr
    out = subprocess.run([str(exe), "identifiability", "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)  # the whole JSON document arrived through the pipe
