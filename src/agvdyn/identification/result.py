"""The result of an identification: parameters, uncertainty, the rows behind them and their account."""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from agvdyn._lazy import pandas as pd

from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.model_fit import linear_values
from agvdyn.identification.rows import RowCounts
from agvdyn.identification.settings import OFFSET_NAMES, IdentificationSettings
from agvdyn.identification.slip import SlipEvent
from agvdyn.model_file import write_model_parameters
from agvdyn.model_spec import EXTRA_NAMES, EXTRA_UNITS, PAPER_MODEL, ModelParameters, ModelSpec
from agvdyn.platform import PARAMETER_NAMES, PARAMETER_UNITS, Geometry, ParameterFile, Parameters, write_parameters

__all__ = ["Identification", "UncertaintySummary", "ParameterCorrelation"]

#: The keys of the uncertainty's details (:func:`agvdyn.identification.uncertainty.parameter_uncertainty`)
#: in the order of the JSON ``uncertainty`` entry; each method has some of them.
_DETAIL_KEYS = ("sigma2", "bandwidth_steps", "correlation_time_steps", "recordings", "blocks", "replicates",
                "block_steps", "max_block_leverage", "blocks_above_half_leverage", "seed")


@dataclass(frozen=True)
class UncertaintySummary:
    """How the std were computed (the JSON ``uncertainty`` entry): ``method`` (``classic``, ``hac``,
    ``jackknife``, ``bootstrap``), the details that method has (None where it has none: ``sigma2``
    for classic; bandwidth, correlation time and recordings for the others; blocks and leverage for
    the jackknife; replicates and seed for the bootstrap) and ``dof``, the degrees of freedom per
    parameter (jackknife; None: infinite) or None."""

    method: str
    sigma2: float | None = None
    bandwidth_steps: int | None = None
    correlation_time_steps: float | None = None
    recordings: int | None = None
    blocks: int | None = None
    replicates: int | None = None
    block_steps: int | None = None
    max_block_leverage: float | None = None
    blocks_above_half_leverage: int | None = None
    seed: int | None = None
    dof: Mapping[str, float | None] | None = None

    @classmethod
    def of(cls, method: str, details: Mapping[str, Any], dof: Mapping[str, float | None] | None = None
           ) -> "UncertaintySummary":
        """From an :class:`~agvdyn.identification.uncertainty.Uncertainty`'s method and details."""
        unknown = sorted(set(details) - set(_DETAIL_KEYS))
        if unknown:
            raise ValueError(f"uncertainty details {unknown}: expected some of {list(_DETAIL_KEYS)}")
        return cls(method, **details, dof=None if dof is None else dict(dof))

    def to_dict(self) -> dict[str, Any]:
        """The JSON entry: ``method``, the details present, ``dof`` when there is one."""
        out: dict[str, Any] = {"method": self.method}
        out.update({k: getattr(self, k) for k in _DETAIL_KEYS if getattr(self, k) is not None})
        if self.dof is not None:
            out["dof"] = dict(self.dof)
        return out


@dataclass(frozen=True)
class ParameterCorrelation:
    """Correlation matrix of the estimated parameters (offsets left out), rounded to 6 decimals:
    ``matrix[i][j]`` between ``names[i]`` and ``names[j]`` (the JSON ``correlation`` entry)."""

    names: tuple[str, ...]
    matrix: tuple[tuple[float, ...], ...]

    def to_dict(self) -> dict[str, Any]:
        return {"names": list(self.names), "matrix": [list(row) for row in self.matrix]}


@dataclass(frozen=True, eq=False)
class Identification:
    """Result of :func:`identify`: parameters with uncertainty and the data behind them.

    Attributes
    ----------
    parameters : all 11 parameters (fixed ones at their given values).
    std : standard deviation of each estimated parameter.
    fixed : names of the parameters taken as known (eq. 24).
    condition_number : ``cond(Theta_1,w^T Theta_1,w)`` of the column-scaled stacked regressor
        (the paper's 11.56); ``condition_number_unscaled`` of ``Theta_1^T Theta_1``.
    residual_rms : RMS of ``tau - Theta p`` over the kept rows, per ``"segment:coordinate"``.
    blocks : the equation blocks (Fig. 5 data), ``notes``: stretches cut or skipped and why.
    rows : account of the samples (used, dropped at edges, slip, in no mode, label mismatches,
        clipped at the stops); ``slip_events``: wheel slip found (:class:`SlipEvent`);
        ``slip_thresholds``: threshold used per log (m/s).
    offsets, offsets_std : estimated motor-torque offsets (motor side, N m) when
        ``settings.fit.torque_offsets``; the model torques of Fig. 5 include them.
        ``condition_number_with_offsets``: cond of the scaled regressor with the offset columns (and
        a model extension's columns).
    model : the resolved :class:`~agvdyn.model_spec.ModelSpec` identified (the paper's by default);
        ``extra``, ``extra_std``: its parameters beyond the paper's (``d_sl, d_sr, d_sw``, ``x_c, y_c``
        estimated, with std, ``inf`` where the data do not determine them; ``w_sl, w_sr, w_sw`` as the
        spec gives them, no std unless a search sets one); ``delay_std_s``: the std of the delay when a
        search found it (None: given).
    residual_ss : ``{coordinate group: (residual sum of squares, rows)}`` over the kept rows.
    search_std : with a searched delay or Stribeck velocity, the std each parameter's ``std`` includes
        for the searched values' uncertainty (:mod:`.search_uncertainty`; JSON ``std_search``).
    """

    parameters: Parameters
    std: dict[str, float]
    fixed: tuple[str, ...]
    condition_number: float
    condition_number_unscaled: float
    residual_rms: dict[str, float]
    n_rows: int
    n_samples: int
    blocks: tuple[EquationBlock, ...]
    settings: IdentificationSettings
    geometry: Geometry
    sources: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    estimator: str = "LeastSquares"
    offsets: dict[str, float] = field(default_factory=dict)
    offsets_std: dict[str, float] = field(default_factory=dict)
    condition_number_with_offsets: float = float("nan")
    rows: RowCounts = field(default_factory=RowCounts)
    slip_events: tuple[SlipEvent, ...] = ()
    slip_thresholds: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    std_classic: dict[str, float] = field(default_factory=dict)
    correlation: ParameterCorrelation | None = None
    uncertainty: UncertaintySummary | None = None
    active_bounds: tuple[str, ...] = ()
    downweighted_rows: int = 0
    quantiles: dict[str, float] = field(default_factory=dict)  # of ci95 per parameter; default 1.96
    #: m_ch / C_ch changed within a recording (:func:`.change.parameter_change_in_store`): time, size, std
    parameter_change: dict[str, Any] | None = None
    model: ModelSpec = PAPER_MODEL
    extra: dict[str, float] = field(default_factory=dict)
    extra_std: dict[str, float] = field(default_factory=dict)
    delay_std_s: float | None = None
    residual_ss: dict[str, tuple[float, int]] = field(default_factory=dict)
    #: what the searched values' uncertainty added to each std (:mod:`.search_uncertainty`)
    search_std: dict[str, float] = field(default_factory=dict)

    def ci95(self, name: str) -> tuple[float, float] | None:
        """95 % interval ``value +- q std`` of an estimated parameter (q: Student's t of the
        uncertainty's degrees of freedom, 1.96 when the variance is taken as known), None for a fixed one;
        the extensions' parameters (:data:`agvdyn.model_spec.EXTRA_NAMES`) alike."""
        std = self.extra_std if name in EXTRA_NAMES else self.std
        if name not in std:
            return None
        v, s = (self.extra[name] if name in EXTRA_NAMES else getattr(self.parameters, name)), std[name]
        q = self.quantiles.get(name, 1.959964)
        return (v - q * s, v + q * s)

    @property
    def model_parameters(self) -> ModelParameters:
        """The identified model: the paper's parameters, the extensions' and the delay (s)."""
        return ModelParameters(self.parameters, dict(self.extra), float(self.model.delay), self.model)

    @property
    def extra_vector(self) -> np.ndarray | None:
        """Values of the model's regression columns (``model.linear_names``: ``d_s``, ``m_ch x_c``,
        ``m_ch y_c``), None for a model without columns."""
        return linear_values(self.model, self.extra, self.parameters)

    def _parameter_entries(self) -> dict[str, dict[str, Any]]:
        """Per parameter value, std, ci95, std_classic; an unbounded interval (not excited) is
        ``std: null, ci95: [null, null], identified: false`` (JSON has no infinity)."""
        out = {}
        for n in PARAMETER_NAMES:
            entry: dict[str, Any] = {"value": getattr(self.parameters, n), "std": self.std.get(n)}
            if n in self.std:
                bounded = math.isfinite(self.std[n])
                entry["ci95"] = list(self.ci95(n)) if bounded else [None, None]
                entry["std_classic"] = self.std_classic.get(n) if bounded else None
                entry["std"] = self.std[n] if bounded else None
                entry["identified"] = bounded
                if n in self.search_std:
                    entry["std_search"] = self.search_std[n]
            out[n] = entry
        for n in EXTRA_NAMES:  # the model's parameters beyond the paper's, when it has them
            if n in self.extra:
                entry = {"value": self.extra[n], "std": None, "unit": EXTRA_UNITS[n]}
                if n in self.extra_std:
                    bounded = math.isfinite(self.extra_std[n])
                    entry.update(std=self.extra_std[n] if bounded else None,
                                 ci95=list(self.ci95(n)) if bounded else [None, None], identified=bounded)
                    if n in self.search_std:
                        entry["std_search"] = self.search_std[n]
                out[n] = entry
        return out

    def _model_entry(self) -> dict[str, Any]:
        """The JSON ``model``: friction law, delay (s) and its std (None: given), com_offset; an unbounded
        delay interval as ``delay_std_s: null`` with ``delay_identified: false`` (JSON has no infinity);
        ``held``: the breakaway levels held at the paper's law, when there are."""
        entry = {"friction": self.model.friction, "delay_s": float(self.model.delay), "delay_std_s": self.delay_std_s,
                 "com_offset": self.model.com_offset}
        if self.delay_std_s is not None and not math.isfinite(self.delay_std_s):
            entry.update(delay_std_s=None, delay_identified=False)
        if self.model.held:  # breakaway levels held at the paper's law (ModelSpec.held)
            entry["held"] = list(self.model.held)
        return entry

    @property
    def offset_vector(self) -> np.ndarray | None:
        """Motor-torque offsets (4,) in wheel order, None when they were not estimated."""
        return np.array([self.offsets[n] for n in OFFSET_NAMES]) if self.offsets else None

    def to_frame(self) -> pd.DataFrame:
        """Parameter table: value, std, relative std, unit, fixed; index = parameter name."""
        rows = []
        for name in PARAMETER_NAMES:
            value = getattr(self.parameters, name)
            std = self.std.get(name, float("nan"))
            rows.append({"name": name, "value": value, "std": std,
                         "rel_std": std / abs(value) if value != 0 else float("nan"),
                         "unit": PARAMETER_UNITS[name], "fixed": name in self.fixed})
        for name in (n for n in EXTRA_NAMES if n in self.extra):
            value, std = self.extra[name], self.extra_std.get(name, float("nan"))
            rows.append({"name": name, "value": value, "std": std,
                         "rel_std": std / abs(value) if value != 0 else float("nan"),
                         "unit": EXTRA_UNITS[name], "fixed": name not in self.extra_std})
        return pd.DataFrame(rows).set_index("name")

    def torques_frame(self) -> pd.DataFrame:
        """Measured and model generalized torques per row (long format, Fig. 5)."""
        p, extra = self.parameters.to_vector(), self.extra_vector
        frames = []
        for b in self.blocks:
            model = b.model_torque(p, self.offset_vector, extra)
            for j, coord in enumerate(b.coordinates):
                frames.append(pd.DataFrame({
                    "source": b.source, "segment": b.segment, "mode": b.mode.label, "coordinate": coord,
                    "t": b.t, "measured": b.torque[:, j], "model": model[:, j], "kept": b.keep[:, j]}))
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def to_parameter_file(self) -> ParameterFile:
        extra = {
            "condition_number_unscaled": self.condition_number_unscaled,
            "residual_rms": dict(self.residual_rms),
            "n_rows": self.n_rows,
            "n_samples": self.n_samples,
            "settings": self.settings.to_dict(),
            "sources": list(self.sources),
            "torque_offsets": {n: {"value": v, "std": self.offsets_std.get(n)} for n, v in self.offsets.items()},
        }
        extra.update(self._data_account())
        return ParameterFile(self.parameters, dict(self.std), self.fixed, self.condition_number, extra,
                             geometry=self.geometry)

    def _data_account(self) -> dict[str, Any]:
        return {
            "estimator": self.estimator,
            "uncertainty": {} if self.uncertainty is None else self.uncertainty.to_dict(),
            "correlation": {} if self.correlation is None else self.correlation.to_dict(),
            "active_bounds": list(self.active_bounds),
            "downweighted_rows": self.downweighted_rows,
            "rows": self.rows.to_dict(),
            "slip_events": [e.to_dict() for e in self.slip_events],
            "dropped_slip_rows": self.rows.slip,
            "slip_threshold_mps": dict(self.slip_thresholds),
        }

    def write(self, path: str | os.PathLike) -> Path:
        """Write the parameter file (YAML, or JSON by suffix) atomically; a model beyond the paper's
        with its parameters inside ``parameters`` and its ``model:`` block (:mod:`agvdyn.model_file`,
        read back by :func:`agvdyn.model_file.read_model_parameters`)."""
        if self.model.is_paper and not self.extra:
            return write_parameters(path, self.to_parameter_file())
        return write_model_parameters(path, self.to_parameter_file(), self.model, self.extra, self.extra_std)

    def to_json_dict(self) -> dict[str, Any]:
        """The summary printed by ``agvdyn identify --json``."""
        return {
            "parameters": self._parameter_entries(),
            "model": self._model_entry(),
            "condition_number": self.condition_number,
            "condition_number_unscaled": self.condition_number_unscaled,
            "condition_number_with_offsets": (None if not math.isfinite(self.condition_number_with_offsets)
                                              else self.condition_number_with_offsets),
            "fixed": list(self.fixed),
            "residual_rms": dict(self.residual_rms),
            "torque_offsets": {n: {"value": v, "std": self.offsets_std.get(n)} for n, v in self.offsets.items()},
            "n_rows": self.n_rows,
            "n_samples": self.n_samples,
            "filtering": self.settings.rows.filtering.value,
            "sources": list(self.sources),
            "notes": list(self.notes),
            "warnings": list(self.warnings),
            "parameter_change": self.parameter_change,
            "platform": self.geometry.to_dict(),
            **self._data_account(),
        }

