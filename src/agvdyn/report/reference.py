"""What identified parameters are compared with, if anything, and the parameter table.

A comparison only makes sense against values of the same vehicle: a parameter file given by
the user (``--reference``), the simulator's true parameters recorded in a log's sidecar, or
Table 2 of the paper when the platform is the paper's prototype. For any other vehicle there
is no reference and the report shows no deviation column.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import pandas as pd

from agvdyn.platform import (
    PAPER_PARAMETERS,
    PAPER_STD,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    PROTOTYPE,
    Geometry,
    Parameters,
    read_parameters,
)

__all__ = ["Reference", "TABLE2", "choose_reference", "reference_from_file", "sidecar_truth", "parameter_table"]


@dataclass(frozen=True)
class Reference:
    """Parameters to compare with: ``kind`` is ``file`` (given by the user), ``truth`` (a
    simulator's sidecar) or ``paper`` (Table 2); ``label`` says which in words."""

    parameters: Parameters
    std: Mapping[str, float] = field(default_factory=dict)
    label: str = "paper, Table 2"
    kind: Literal["file", "truth", "paper"] = "paper"


#: Table 2 of the paper (with B_w = 0.121), the reference for the prototype.
TABLE2 = Reference(PAPER_PARAMETERS, dict(PAPER_STD), "paper, Table 2", "paper")


def reference_from_file(path: str | os.PathLike) -> Reference:
    """A parameter file (YAML/JSON) as the reference; errors as :func:`agvdyn.platform.read_parameters`."""
    content = read_parameters(path)
    return Reference(content.parameters, dict(content.std), f"reference file {os.fspath(path)}", "file")


def sidecar_truth(logs: Sequence[Any]) -> Reference | None:
    """The simulator's true parameters from a log sidecar (``true_parameters``, or ``parameters``),
    None when no log carries all eleven."""
    for log in logs:
        side = getattr(log, "sidecar", None) or {}
        for key in ("true_parameters", "parameters"):
            data = side.get(key)
            if isinstance(data, dict):
                values = {n: (v.get("value") if isinstance(v, dict) else v) for n, v in data.items()}
                if all(isinstance(values.get(n), (int, float)) for n in PARAMETER_NAMES):
                    return Reference(Parameters(**{n: float(values[n]) for n in PARAMETER_NAMES}), {},
                                     f"simulator truth, sidecar {key}", "truth")
    return None


def choose_reference(logs: Sequence[Any], geometry: Geometry, reference: Reference | None = None) -> Reference | None:
    """The reference of a report: the one given, else the simulator truth of a sidecar, else Table 2
    when ``geometry`` is the paper's prototype (PLATFORM.md), else None (another vehicle)."""
    if reference is not None:
        return reference
    truth = sidecar_truth(logs)
    if truth is not None:
        return truth
    return TABLE2 if geometry.same_shape(PROTOTYPE) else None


def parameter_table(identification, reference: Parameters | Reference | None = PAPER_PARAMETERS,
                    reference_std: Mapping[str, float] | None = PAPER_STD, *, rel_tolerance: float = 0.05,
                    n_std: float = 3.0) -> pd.DataFrame:
    """The identified parameters, with a reference alongside when one is given.

    Columns: ``value``, ``std``, ``ci_low``, ``ci_high`` (95 %), ``unit``, ``fixed``, and the
    comparison ``reference``, ``reference_std``, ``deviation_pct`` (100 (value / reference - 1)),
    ``deviation_in_std`` (|value - reference| / std) and ``ok``: within ``rel_tolerance`` of the
    reference or within ``n_std`` standard deviations, whichever is wider (the acceptance rule of
    issue 4). Without a reference the comparison columns are NaN / None; fixed parameters have
    ``ok`` = None.
    """
    if isinstance(reference, Reference):
        reference, reference_std = reference.parameters, reference.std
    reference_std = reference_std or {}
    rows = []
    for name in PARAMETER_NAMES:
        value = getattr(identification.parameters, name)
        std = identification.std.get(name, math.nan)
        ci = identification.ci95(name) if name in identification.std else None
        fixed = name in identification.fixed
        row: dict[str, Any] = {
            "name": name, "value": value, "std": std, "ci_low": ci[0] if ci else math.nan,
            "ci_high": ci[1] if ci else math.nan, "unit": PARAMETER_UNITS[name], "fixed": fixed,
            "reference": math.nan, "reference_std": math.nan, "deviation_pct": math.nan,
            "deviation_in_std": math.nan, "ok": None}
        if reference is not None:
            ref = getattr(reference, name)
            dev = value - ref
            row.update(
                reference=ref, reference_std=reference_std.get(name, math.nan),
                deviation_pct=100 * (value / ref - 1) if ref else math.nan,
                deviation_in_std=abs(dev) / std if std and math.isfinite(std) and std > 0 else math.nan,
                ok=None if fixed else bool(abs(dev) <= max(rel_tolerance * abs(ref),
                                                           n_std * std if math.isfinite(std) else 0)))
        rows.append(row)
    return pd.DataFrame(rows).set_index("name")
