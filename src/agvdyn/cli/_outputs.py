"""The first step of every command that writes: no output over one of its inputs.

The rule is :func:`agvdyn._files.check_outputs`; this module names the inputs the way the commands
read them (a log together with its sidecar, a trajectory file given as EXPERIMENT) and turns a refusal
into exit code 2. Table of every command's inputs and outputs: docs/cli.md, "Outputs never overwrite inputs".
"""
from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Optional

from agvdyn._files import OutputPathError, check_outputs
from agvdyn.cli._app import fail

#: Suffixes by which EXPERIMENT names a trajectory file (agvdyn.trajectories.experiment)
TRAJECTORY_SUFFIXES = (".csv", ".yaml", ".yml")
#: ``kinds`` of a command that writes a log and its YAML sidecar (convert, simulate)
LOG_AND_SIDECAR = {"--out": "log", "sidecar of --out": "sidecar"}

PathLike = Optional[str | os.PathLike]


def sidecar_of(path: str | os.PathLike) -> Path:
    """The YAML sidecar written and read beside a log (``agvdyn.io.sidecar_path``)."""
    from agvdyn.io.log import sidecar_path

    return sidecar_path(path)


def log_inputs(role: str, paths: Iterable[PathLike]) -> dict[str, Path]:
    """Each log of ``paths`` and the sidecar read with it: ``{"LOG 1": ..., "sidecar of LOG 1": ...}``
    (``role`` without a number for a single log; a bag directory has no sidecar)."""
    given = [Path(p) for p in paths if p is not None]
    out: dict[str, Path] = {}
    for i, path in enumerate(given, 1):
        name = role if len(given) == 1 else f"{role} {i}"
        out[name] = path
        if not path.is_dir():
            out[f"sidecar of {name}"] = sidecar_of(path)
    return out


def trajectory_input(experiment: str, role: str = "EXPERIMENT") -> dict[str, Path]:
    """``{"trajectory file EXPERIMENT": path}`` when the experiment is a file, ``{}`` for a built-in name."""
    path = Path(experiment)
    if path.suffix.lower() in TRAJECTORY_SUFFIXES or path.is_file():
        return {f"trajectory file {role}": path}
    return {}


def refuse_overwrite(outputs: Mapping[str, PathLike], inputs: Mapping[str, PathLike],
                     kinds: Optional[Mapping[str, str]] = None) -> None:
    """:func:`agvdyn._files.check_outputs`, a refusal as exit code 2."""
    try:
        check_outputs(outputs, inputs, kinds=kinds)
    except OutputPathError as exc:
        raise fail(str(exc)) from exc
