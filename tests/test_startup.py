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
