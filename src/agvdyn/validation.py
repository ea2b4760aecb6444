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
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from agvdyn.identification import EquationBlock, IdentificationSettings, load_logs, log_equations, platform_for
from agvdyn.platform import Geometry, ParameterFile, Parameters, read_parameters

__all__ = ["Validation", "validate", "nrmse"]


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
    parameters : the parameters validated.
    blocks : equation blocks of the validation log (measured torques, regressor, stiction mask).
    table : per ``"segment:coordinate"``: ``nrmse`` (all rows), ``nrmse_moving`` (stiction rows
        left out), ``rms_error``, ``rms_measured``, ``n_rows``, ``n_moving``.
    """

    parameters: Parameters
    blocks: tuple[EquationBlock, ...]
    table: pd.DataFrame
    settings: IdentificationSettings
    geometry: Geometry
    source: str = ""
    notes: tuple[str, ...] = ()

    @property
    def nrmse(self) -> dict[str, float]:
        """NRMSE per generalized coordinate over all rows (stiction rows included)."""
        return self.table["nrmse"].to_dict()

    @property
    def nrmse_moving(self) -> dict[str, float]:
        """NRMSE per generalized coordinate without the stiction rows."""
        return self.table["nrmse_moving"].to_dict()

    def to_frame(self) -> pd.DataFrame:
        return self.table.copy()

    def torques_frame(self) -> pd.DataFrame:
        """Measured and predicted generalized torques per row (long format, Fig. 6)."""
        p = self.parameters.to_vector()
        frames = []
        for b in self.blocks:
            model = b.model_torque(p)
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
            "rows": {k: int(v) for k, v in self.table["n_rows"].items()},
            "filtering": self.settings.rows.filtering.value,
            "notes": list(self.notes),
        }


def _as_parameters(params: Parameters | ParameterFile | str | os.PathLike) -> Parameters:
    if isinstance(params, Parameters):
        return params
    if isinstance(params, ParameterFile):
        return params.parameters
    return read_parameters(params).parameters


def _table(blocks: Sequence[EquationBlock], p: np.ndarray) -> pd.DataFrame:
    pooled: dict[str, list[list[np.ndarray]]] = {}
    for b in blocks:
        model = b.model_torque(p)
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
    return pd.DataFrame(rows).set_index("coordinate")


def validate(log: Any, params: Parameters | ParameterFile | str | os.PathLike,
             platform: Geometry | str | os.PathLike | None = None, *,
             settings: IdentificationSettings = IdentificationSettings()) -> Validation:
    """Predict the generalized torques of an unseen log and compare with the measured ones (Fig. 6).

    Parameters
    ----------
    log : path or :class:`agvdyn.io.Log` (typically the lane change in mode 2).
    params : identified parameters (Parameters, ParameterFile or parameter file path).
    platform : Geometry or platform file; default the log sidecar's platform, else the prototype.
    settings : the same signal settings as the identification (filter, filtering, stiction).

    Returns
    -------
    Validation
        NRMSE per generalized coordinate with and without the stiction rows.
    """
    (log,) = load_logs([log])
    parameters = _as_parameters(params)
    geometry = platform_for([log], platform)
    blocks, notes = log_equations(log, geometry, settings)
    if not blocks:
        raise ValueError(f"{getattr(log, 'path', None) or '<log>'}: no row in a motion mode to validate on "
                         "(the chassis moves with steering angles of no mode of eq. 9, or stands still)")
    table = _table(blocks, parameters.to_vector())
    return Validation(parameters, tuple(blocks), table, settings, geometry,
                      str(getattr(log, "path", None) or "<log>"), tuple(notes))


def write_validation(path: str | os.PathLike, validation: Validation) -> Path:
    """Write the NRMSE table as JSON atomically."""
    import json

    from agvdyn._files import write_text_atomically

    return write_text_atomically(path, json.dumps(validation.to_json_dict(), indent=2))
