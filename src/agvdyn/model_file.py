"""Parameter files of a model beyond the paper (issue 30; :mod:`agvdyn.model_spec`).

The paper's parameter file (:func:`agvdyn.platform.read_parameters`, ``write_parameters``) with the
extensions' named parameters (:data:`agvdyn.model_spec.EXTRA_NAMES`) inside ``parameters`` next to the
paper's eleven, each ``{value, unit, std, fixed}`` alike, and a ``model:`` block (the
:class:`~agvdyn.model_spec.ModelSpec`, the delay in seconds)::

    parameters:
      C_l: {value: 0.334, unit: kg m^2, std: 0.002, fixed: false}
      ...
      d_sl: {value: 16.9, unit: N m, std: 0.4, fixed: false}
      w_sl: {value: 0.05, unit: rad/s, fixed: true}
    model: {friction: stribeck, delay: 0.004, com_offset: false, stribeck_velocities: [0.05, 0.05, 0.05]}

A file without a ``model:`` block is the paper's model; readers of the paper's file ignore the rest.
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from agvdyn._files import write_text_atomically
from agvdyn.model_spec import EXTRA_NAMES, EXTRA_UNITS, ModelParameters, ModelSpec, model_from_mapping
from agvdyn.platform import ParameterFile, PlatformFileError, read_parameters

__all__ = ["extra_parameter_entries", "write_model_parameters", "read_model_parameters"]


def extra_parameter_entries(extra: Mapping[str, float], std: Mapping[str, float]) -> dict[str, dict[str, Any]]:
    """The ``parameters`` entries of the extensions' parameters: ``value``, ``unit``, ``std`` (when
    estimated; ``inf`` where the data do not determine it) and ``fixed`` (given, not estimated)."""
    out: dict[str, dict[str, Any]] = {}
    for name in EXTRA_NAMES:
        if name not in extra:
            continue
        entry: dict[str, Any] = {"value": float(extra[name]), "unit": EXTRA_UNITS[name]}
        if name in std:
            entry["std"] = float(std[name])
        entry["fixed"] = name not in std
        out[name] = entry
    return out


def write_model_parameters(path: str | os.PathLike, content: ParameterFile, model: ModelSpec,
                           extra: Mapping[str, float], std: Mapping[str, float]) -> Path:
    """Write a parameter file (YAML, or JSON by suffix) atomically: ``content`` as
    :func:`agvdyn.platform.write_parameters` writes it, the extensions' parameters ``extra`` (with
    ``std``) inside ``parameters`` and the ``model:`` block of a model that is not the paper's."""
    data = content.to_dict()
    data["parameters"].update(extra_parameter_entries(extra, std))
    if not model.is_paper:
        data["model"] = model.to_dict()
    text = json.dumps(data, indent=2) if str(path).lower().endswith(".json") else yaml.safe_dump(data, sort_keys=False)
    return write_text_atomically(path, text)


def read_model_parameters(path: str | os.PathLike) -> ModelParameters:
    """The model of a parameter file: the paper's parameters (:func:`agvdyn.platform.read_parameters`),
    the ``model:`` block (none: the paper's model) and the extensions' parameters it needs from
    ``parameters`` (the Stribeck velocities may come from the block's ``stribeck_velocities``).

    Raises :class:`agvdyn.platform.PlatformFileError` naming the file and the key: a bad ``model:``
    block, a delay ``'auto'`` (a file holds a resolved model), a missing or non-numeric parameter.
    """
    path = Path(path)
    content = read_parameters(path)
    data = _mapping(path)
    try:
        spec = model_from_mapping(data.get("model"), where=f"{path}: model")
    except ValueError as exc:
        raise PlatformFileError(str(exc)) from None
    if spec.delay == "auto":
        raise PlatformFileError(f"{path}: model: delay='auto': expected the delay in seconds (a parameter file holds "
                                "an identified model)")
    table = data.get("parameters", data)
    extra = {n: _value(path, n, table[n]) for n in EXTRA_NAMES if isinstance(table, Mapping) and n in table}
    if spec.stribeck_velocities is not None:
        for name, value in zip(("w_sl", "w_sr", "w_sw"), spec.stribeck_velocities):
            extra.setdefault(name, value)
    try:
        return ModelParameters(content.parameters, extra, float(spec.delay), spec)
    except ValueError as exc:
        raise PlatformFileError(f"{path}: {exc}") from None


def _mapping(path: Path) -> dict[str, Any]:
    text = path.read_text(encoding="utf-8")  # read_parameters has read it: it exists and is text
    data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    return data if isinstance(data, dict) else {}


def _value(path: Path, name: str, entry: Any) -> float:
    value = entry.get("value") if isinstance(entry, Mapping) else entry
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise PlatformFileError(f"{path}: parameters: {name}={value!r}: expected a finite number")
    return float(value)
