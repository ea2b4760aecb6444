"""Build time only: setuptools' ``build_ext`` for the C++ extension ``agvdyn.ffcpp._core``.

Named in pyproject.toml (``[tool.setuptools.cmdclass]``); never imported by agvdyn at run time.
It configures ``cpp/`` with CMake (``AGVDYN_FF_PYTHON=ON``: the library ``agvdyn_ff`` and the
nanobind module only), builds it in a fresh directory under ``build/`` and lets CMake write the
module where setuptools expects it (the editable install then copies it into
``src/agvdyn/ffcpp/``). The extension is optional: when CMake or the C++ compiler is missing or
the build fails, the reason is printed and agvdyn installs without it (``agvdyn.ffcpp`` says so at
run time), unless ``AGVDYN_REQUIRE_CPP=1``. ``CMAKE_ARGS`` (environment) adds CMake arguments.
"""
from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools.command.build_ext import build_ext


def _tool(name: str) -> str | None:
    """A build tool from PATH or from its PyPI package (cmake, ninja in the build environment)."""
    found = shutil.which(name)
    if found:
        return found
    try:
        module = __import__(name)
        candidate = Path(getattr(module, f"{name.upper()}_BIN_DIR", "")) / name
    except (ImportError, TypeError):
        return None
    return str(candidate) if candidate.exists() else None


class CMakeBuildExt(build_ext):
    """Build the extensions of this project with cpp/CMakeLists.txt instead of the compiler of distutils."""

    def build_extension(self, ext) -> None:  # noqa: D102 - setuptools hook
        root = Path(__file__).resolve().parents[2]
        if not (root / "cpp" / "CMakeLists.txt").exists():
            root = Path.cwd()
        target = Path(self.get_ext_fullpath(ext.name)).resolve()
        build_dir = Path(self.build_temp).resolve() / "agvdyn_ff"
        target.unlink(missing_ok=True)  # never ship a module left over from an earlier build
        cmake = _tool("cmake")
        if cmake is None:
            return self._skip(ext, "cmake not found (Debian: apt-get install cmake, or pip install cmake)")
        shutil.rmtree(build_dir, ignore_errors=True)
        configure = [cmake, "-S", str(root / "cpp"), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
                     "-DAGVDYN_FF_PYTHON=ON", f"-DPython_EXECUTABLE={sys.executable}",
                     f"-DAGVDYN_FF_PYTHON_OUTPUT_DIR={target.parent}"]
        ninja = _tool("ninja")
        if ninja is not None:
            configure += ["-G", "Ninja", f"-DCMAKE_MAKE_PROGRAM={ninja}"]
        configure += shlex.split(os.environ.get("CMAKE_ARGS", ""))  # extra -D... as other CMake-based builds take them
        jobs = str(os.cpu_count() or 2)
        try:
            subprocess.run(configure, check=True)
            subprocess.run([cmake, "--build", str(build_dir), "--parallel", jobs], check=True)
        except (OSError, subprocess.CalledProcessError) as exc:
            return self._skip(ext, f"the CMake build of cpp/ failed ({exc}); a C++17 compiler is needed "
                                   "(Debian: apt-get install g++)")
        if not target.exists():
            return self._skip(ext, f"CMake did not write {target}")
        return None

    def _skip(self, ext, reason: str) -> None:
        message = f"agvdyn: building the optional C++ extension {ext.name} failed: {reason}"
        if os.environ.get("AGVDYN_REQUIRE_CPP") == "1":
            raise RuntimeError(message)
        print(f"WARNING: {message}; installing agvdyn without it (--engine cpp unavailable)", file=sys.stderr)
