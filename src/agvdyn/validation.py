"""Validation of identified parameters on an unseen log (paper sec. 7, Fig. 6).

The generalized torques ``H_k^T B u`` measured on a log the identification did not use (the
lane change in the car-like mode 2) are compared with the model's ``H_k^T Theta p``, both
computed by the same signal path as the identification (:func:`agvdyn.identification.log_equations`).

NRMSE, per generalized coordinate (pooled over the runs of one segment)::

    NRMSE = RMS(tau_measured - tau_model) / RMS(tau_measured)

i.e. normalised by the RMS of the measured signal, not by its range: 0 is a perfect
prediction, 1 is as good as predicting zero. It is reported over all rows of the runs
("with stiction rows", as the paper's Fig. 6) and over the rows whose generalized velocity
is above the stiction threshold ("without stiction rows").

A model beyond the paper (issue 30, :class:`agvdyn.model_spec.ModelParameters`, or a parameter file
with a ``model:`` block, :func:`agvdyn.model_file.read_model_parameters`) predicts with its
extensions through the same rows as its identification (:mod:`agvdyn.identification.model_rows`):
Stribeck friction per joint group and the off-centre chassis as the extra columns of each block;
a torque delay ``delay_s`` by reading the *measured* torques at ``t + delay_s`` (the torque logged
at t acted at ``t - delay_s``), so that measured and predicted torques belong to the same motion;
the prediction is never shifted. The paper model's and an extended model's NRMSE on one log are
therefore comparable: both are normalised by the RMS of the measured torques they are compared with
(with a delay, the same samples shifted).
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from agvdyn._lazy import pandas as pd  # the table only: validating a log needs no pandas (~0.3 s of start-up)

from agvdyn.identification import (EquationBlock, IdentificationSettings, load_logs, log_equations, log_rows,
                                   platform_for)
from agvdyn.identification.model_fit import linear_values
from agvdyn.model_file import read_model_parameters
from agvdyn.model_spec import STRIBECK_NAMES, ModelParameters, ModelSpec
from agvdyn.platform import Geometry, ParameterFile, Parameters

__all__ = ["Validation", "validate", "nrmse", "validation_score"]


def nrmse(measured: np.ndarray, model: np.ndarray) -> float:
    """RMS(measured - model) / RMS(measured); NaN when there is no sample or the measurement is zero."""
    measured = np.asarray(measured, dtype=float)
    model = np.asarray(model, dtype=float)
    if measured.size == 0:
        return float("nan")
    ref = math.sqrt(float(np.mean(measured**2)))
    if ref == 0:
        return float("nan")
    return math.sqrt(float(np.mean((measured - model) ** 2))) / ref


@dataclass(frozen=True, eq=False)
class Validation:
    """Result of :func:`validate`.

    Attributes
    ----------
    parameters : the parameters validated (the paper's 11).
    blocks : equation blocks of the validation log (measured torques, regressor, stiction mask; the
        extensions' columns and delayed torques of an extended model).
    rows : per ``"segment:coordinate"`` (``coordinate``): ``nrmse`` (all rows), ``nrmse_moving``
        (stiction rows left out), ``rms_error``, ``rms_measured``, ``n_rows``, ``n_moving``; :attr:`table`
        holds them as a DataFrame indexed by ``coordinate``.
    model : the model validated (:class:`~agvdyn.model_spec.ModelParameters`; the paper's model of
        ``parameters`` when not given).
    """

    parameters: Parameters
    blocks: tuple[EquationBlock, ...]
    rows: tuple[dict[str, Any], ...]
    settings: IdentificationSettings
    geometry: Geometry
    source: str = ""
    notes: tuple[str, ...] = ()
    model: ModelParameters | None = None

    def __post_init__(self) -> None:
        if self.model is None:
            object.__setattr__(self, "model", ModelParameters(self.parameters))

    @property
    def extra_vector(self) -> np.ndarray | None:
        """Values of the extensions' columns of the blocks (``model.spec.linear_names``), None without."""
        return linear_values(self.model.spec, self.model.extra, self.parameters)

    @cached_property
    def table(self) -> pd.DataFrame:
        """:attr:`rows` as a DataFrame indexed by ``coordinate`` (made on first use)."""
        return pd.DataFrame(list(self.rows)).set_index("coordinate")

    def _column(self, name: str) -> dict[str, Any]:
        return {row["coordinate"]: row[name] for row in self.rows}

    @property
    def nrmse(self) -> dict[str, float]:
        """NRMSE per generalized coordinate over all rows (stiction rows included)."""
        return self._column("nrmse")

    @property
    def nrmse_moving(self) -> dict[str, float]:
        """NRMSE per generalized coordinate without the stiction rows."""
        return self._column("nrmse_moving")

    def to_frame(self) -> pd.DataFrame:
        return self.table.copy()

    def torques_frame(self) -> pd.DataFrame:
        """Measured and predicted generalized torques per row (long format, Fig. 6)."""
        p, x = self.parameters.to_vector(), self.extra_vector
        frames = []
        for b in self.blocks:
            model = b.model_torque(p, extra=x)
            for j, coord in enumerate(b.coordinates):
                frames.append(pd.DataFrame({
                    "source": b.source, "segment": b.segment, "mode": b.mode.label, "coordinate": coord,
                    "t": b.t, "measured": b.torque[:, j], "model": model[:, j], "kept": b.keep[:, j]}))
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def to_json_dict(self) -> dict[str, Any]:
        def clean(x: float) -> float | None:
            return None if not math.isfinite(x) else float(x)

        return {
            "source": self.source,
            "nrmse": {k: clean(v) for k, v in self.nrmse.items()},
            "nrmse_without_stiction": {k: clean(v) for k, v in self.nrmse_moving.items()},
            "definition": "RMS(measured - model) / RMS(measured) per generalized coordinate",
            "rows": {k: int(v) for k, v in self._column("n_rows").items()},
            "filtering": self.settings.rows.filtering.value,
            "notes": list(self.notes),
            "model": {"friction": self.model.spec.friction, "delay_s": self.model.delay_s,
                      "com_offset": self.model.spec.com_offset},
        }


def _as_model(params: Parameters | ModelParameters | ParameterFile | str | os.PathLike) -> ModelParameters:
    if isinstance(params, ModelParameters):
        return params
    if isinstance(params, Parameters):
        return ModelParameters(params)
    if isinstance(params, ParameterFile):
        return ModelParameters(params.parameters)
    return read_model_parameters(params)


def _row_model(model: ModelParameters) -> ModelSpec:
    """The resolved spec of the model's rows: its delay in seconds, its Stribeck velocities."""
    velocities = tuple(model.value(n) for n in STRIBECK_NAMES) if model.spec.stribeck else None
    return model.spec.replace(delay=model.delay_s, stribeck_velocities=velocities)


def _table_rows(blocks: Sequence[EquationBlock], p: np.ndarray, x: np.ndarray | None = None
                ) -> tuple[dict[str, Any], ...]:
    pooled: dict[str, list[list[np.ndarray]]] = {}
    for b in blocks:
        model = b.model_torque(p, extra=x)
        for j, coord in enumerate(b.coordinates):
            entry = pooled.setdefault(f"{b.segment}:{coord}", [[], [], []])
            entry[0].append(b.torque[:, j])
            entry[1].append(model[:, j])
            entry[2].append(b.keep[:, j])
    rows = []
    for key, (meas, mod, keep) in pooled.items():
        meas, mod, keep = np.concatenate(meas), np.concatenate(mod), np.concatenate(keep)
        rows.append({
            "coordinate": key,
            "nrmse": nrmse(meas, mod),
            "nrmse_moving": nrmse(meas[keep], mod[keep]),
            "rms_error": float(np.sqrt(np.mean((meas - mod) ** 2))),
            "rms_measured": float(np.sqrt(np.mean(meas**2))),
            "n_rows": int(meas.size),
            "n_moving": int(keep.sum()),
        })
    return tuple(rows)


def validate(log: Any, params: Parameters | ModelParameters | ParameterFile | str | os.PathLike,
             platform: Geometry | str | os.PathLike | None = None, *,
             settings: IdentificationSettings = IdentificationSettings()) -> Validation:
    """Predict the generalized torques of an unseen log and compare with the measured ones (Fig. 6).

    Parameters
    ----------
    log : path or :class:`agvdyn.io.Log` (typically the lane change in mode 2).
    params : identified parameters (Parameters, ParameterFile or parameter file path: the paper's
        model) or model (ModelParameters, or a parameter file path with a ``model:`` block: the
        model beyond the paper, see the module docstring).
    platform : Geometry or platform file; default the log sidecar's platform, else the prototype.
    settings : the same signal settings as the identification (filter, filtering, stiction).

    Returns
    -------
    Validation
        NRMSE per generalized coordinate with and without the stiction rows.
    """
    (log,) = load_logs([log])
    model = _as_model(params)
    parameters = model.parameters
    geometry = platform_for([log], platform)
    spec = _row_model(model)
    if spec.is_paper:
        blocks, notes = log_equations(log, geometry, settings)
    else:
        rows = log_rows(log, geometry, settings, model=spec)
        blocks, notes = list(rows.blocks), list(rows.notes)
    if not blocks:
        raise ValueError(f"{getattr(log, 'path', None) or '<log>'}: no row in a motion mode to validate on "
                         "(the chassis moves with steering angles of no mode of eq. 9, or stands still)")
    x = linear_values(model.spec, model.extra, parameters)
    return Validation(parameters, tuple(blocks), _table_rows(blocks, parameters.to_vector(), x), settings, geometry,
                      str(getattr(log, "path", None) or "<log>"), tuple(notes), model)


def write_validation(path: str | os.PathLike, validation: Validation) -> Path:
    """Write the NRMSE table as JSON atomically."""
    import json

    from agvdyn._files import write_text_atomically

    return write_text_atomically(path, json.dumps(validation.to_json_dict(), indent=2))


def validation_score(log: Any, identification: Any, settings: IdentificationSettings = IdentificationSettings()
                     ) -> float:
    """The score of an identification on a log it did not use (lower is better): the mean over
    coordinates of :func:`validate`'s NRMSE without stiction rows (``nrmse_moving``, the rows the fit
    models), with the identification's model (its extensions too); nan when no coordinate has one.
    What :func:`agvdyn.identification.compare_models` takes as ``validation``."""
    model = getattr(identification, "model_parameters", identification.parameters)
    values = [v for v in validate(log, model, identification.geometry, settings=settings).nrmse_moving.values()
              if math.isfinite(v)]
    return float(sum(values) / len(values)) if values else math.nan
