"""Settings of the identification, one frozen object per stage, and the names the stages share (paper sec. 6-7).

:class:`IdentificationSettings` holds the settings of each stage of the pipeline:

* ``rows``: :class:`~agvdyn.row_rules.RowSettings` (filter, stretches, modes, slip, stiction thresholds
  and guards, segments, torque timing), defined low in :mod:`agvdyn.row_rules` so that the planner
  predicts the same rows;
* ``fit``: :class:`~.stage_settings.FitSettings` (columns, estimator, rank and quality checks, plausibility);
* ``uncertainty``: :class:`~.stage_settings.UncertaintySettings` (method, bandwidth, bootstrap).

``to_dict`` writes them as one flat mapping (its keys are the parameter files' and JSON's ``settings``);
:meth:`IdentificationSettings.from_flat` builds them from those flat names (batch manifests, study options).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from agvdyn.identification.stage_settings import (
    EstimatorName,
    FitSettings,
    RobustLoss,
    UncertaintyMethod,
    UncertaintySettings,
    Unexcited,
)
from agvdyn.row_rules import CHASSIS_COORDINATES, NON_NEGATIVE, STEERING_COORDINATES, Filtering, RowSettings

__all__ = [
    "DEFAULT_FIXED", "OFFSET_NAMES", "EXCITATION", "STEERING_COORDINATES", "CHASSIS_COORDINATES",
    "Filtering", "IdentificationSettings", "RowSettings", "FitSettings", "UncertaintySettings", "EstimatorName",
    "RobustLoss", "Unexcited", "UncertaintyMethod",
]

#: Parameters taken as known by default (eq. 24): B_w from a single-axis test (sec. 7).
DEFAULT_FIXED: Mapping[str, float] = MappingProxyType({"B_w": 0.121})

#: Names of the motor-torque offsets (nuisance parameters, motor side, N m).
OFFSET_NAMES = ("offset_fl", "offset_rl", "offset_fr", "offset_rr")

#: Which experiment excites each parameter (Table 1, PLATFORM.md segment names).
EXCITATION: Mapping[str, str] = MappingProxyType({
    "C_l": "steer_left (mode 1: steering the left wheel set at rest)",
    "d_vl": "steer_left (mode 1: steering the left wheel set at rest)",
    "d_cl": "steer_left (mode 1: steering the left wheel set at rest)",
    "C_r": "steer_right (mode 1: steering the right wheel set at rest)",
    "d_vr": "steer_right (mode 1: steering the right wheel set at rest)",
    "d_cr": "steer_right (mode 1: steering the right wheel set at rest)",
    "m_ch": "straight (mode 2 with alpha_v = 0) or lateral (mode 3)",
    "C_ch": "rotation (mode 4)",
    "d_vw": "straight, lateral or rotation",
    "d_cw": "straight, lateral or rotation",
    "B_w": "the lifted-wheel test (agvdyn simulate/identify lifted-wheel: wheels off the ground), then --fix "
           "B_w=VALUE; or, on the floor, fast rotation plus tight car-like turns (agvdyn simulate car-like, about "
           "2 min: B_w to ~3-4 %, as the inertia seen at the contact points)",
    **dict.fromkeys(OFFSET_NAMES, "the four identification segments together (steer_left, steer_right, straight and "
                                  "rotation each see another combination of the motor offsets), or no offset "
                                  "estimation (--no-offsets)"),
    # the model extensions' columns (agvdyn.model_spec): breakaway levels, m_ch x_c and m_ch y_c
    **{f"d_s{g}": f"{what} with rows at joint rates below the Stribeck velocity w_s{g} (slow reversals; the "
                  f"stiction threshold and guard drop them: lower {threshold})"
       for g, what, threshold in (("l", "steer_left", "steering_threshold"), ("r", "steer_right", "steering_threshold"),
                                  ("w", "straight, lateral or rotation", "stiction_threshold"))},
    **dict.fromkeys(("x_c", "y_c"), "translation with rotation: car-like turns (agvdyn simulate car-like, or a lane "
                                    "change); straight, lateral and rotation alone leave the centre of mass unseen"),
})


#: Flat names of the uncertainty stage's fields (the ``settings`` keys of files and manifests).
_UNCERTAINTY_KEYS: Mapping[str, str] = MappingProxyType({
    "uncertainty": "method", "bandwidth": "bandwidth", "bandwidth_factor": "bandwidth_factor",
    "min_bandwidth": "min_bandwidth", "bootstrap_replicates": "bootstrap_replicates", "seed": "seed"})
_ROW_KEYS = tuple(f.name for f in dataclasses.fields(RowSettings))
_FIT_KEYS = tuple(f.name for f in dataclasses.fields(FitSettings))
#: Every flat name :meth:`IdentificationSettings.from_flat` takes, stage by stage.
FLAT_NAMES: Mapping[str, str] = MappingProxyType({**dict.fromkeys(_ROW_KEYS, "rows"), **dict.fromkeys(_FIT_KEYS, "fit"),
                                                  **dict.fromkeys(_UNCERTAINTY_KEYS, "uncertainty")})


@dataclass(frozen=True)
class IdentificationSettings:
    """Settings of :func:`agvdyn.identification.identify`: one frozen object per stage.

    rows : :class:`~agvdyn.row_rules.RowSettings`, which samples become rows of eq. (19) (filter,
        stretches, modes, slip, stiction thresholds and guards, segments, torque timing).
    fit : :class:`~.stage_settings.FitSettings`, the regression (offset columns, estimator, bounds, rank
        and quality checks, plausibility).
    uncertainty : :class:`~.stage_settings.UncertaintySettings`, the covariance of the estimates.

    ``IdentificationSettings.from_flat(steering_guard=2, estimator="ols")`` builds them from the flat
    names of :meth:`to_dict` (and of batch manifests); :meth:`replace` changes some by those names.
    """

    rows: RowSettings = RowSettings()
    fit: FitSettings = FitSettings()
    uncertainty: UncertaintySettings = UncertaintySettings()

    def __post_init__(self) -> None:
        for name, kind in (("rows", RowSettings), ("fit", FitSettings), ("uncertainty", UncertaintySettings)):
            if not isinstance(getattr(self, name), kind):
                raise TypeError(f"IdentificationSettings {name}={getattr(self, name)!r}: expected a {kind.__name__} "
                                "(IdentificationSettings.from_flat takes the flat names)")
        if self.rows.segments is not None:
            from agvdyn.io import SEGMENTS

            unknown = [n for n in self.rows.segments if n not in SEGMENTS]
            if unknown:
                raise ValueError(f"unknown segment names {unknown}: expected some of {list(SEGMENTS)}")
            if not self.rows.segments:
                raise ValueError(f"no segment names given: expected some of {list(SEGMENTS)}")

    @classmethod
    def from_flat(cls, **keywords: Any) -> "IdentificationSettings":
        """The settings from the flat names of :meth:`to_dict`'s keys (``stiction_guard``, ``estimator``,
        ``uncertainty``, ...; ``filter``, a :class:`~agvdyn.row_rules.FilterSettings`); the rest default."""
        return cls().replace(**keywords)

    def replace(self, **keywords: Any) -> "IdentificationSettings":
        """These settings with some changed by their flat names (see :meth:`from_flat`)."""
        unknown = sorted(set(keywords) - set(FLAT_NAMES))
        if unknown:
            raise TypeError(f"unknown identification setting(s) {unknown}: expected some of {sorted(FLAT_NAMES)}")
        stages: dict[str, dict[str, Any]] = {"rows": {}, "fit": {}, "uncertainty": {}}
        for key, value in keywords.items():
            stage = FLAT_NAMES[key]
            stages[stage][_UNCERTAINTY_KEYS[key] if stage == "uncertainty" else key] = value
        return dataclasses.replace(self, **{stage: dataclasses.replace(getattr(self, stage), **changes)
                                            for stage, changes in stages.items() if changes})

    def to_dict(self) -> dict[str, Any]:
        """One flat mapping of every setting (the ``settings`` of parameter files and JSON: the keys are a contract)."""
        rows, fit, unc = self.rows, self.fit, self.uncertainty
        out: dict[str, Any] = {
            "filter_cutoff_rad_s": rows.filter.cutoff,
            "filter_order": rows.filter.order,
            "derivative": rows.filter.derivative.value,
            "filtering": rows.filtering.value,
            "segments": None if rows.segments is None else list(rows.segments),
            "slip_threshold": rows.slip_threshold,
            "torque_offsets": fit.torque_offsets,
            "torque_lead": rows.torque_lead,
            "plausibility": fit.plausibility,
        }
        for key in NON_NEGATIVE:
            out[key] = getattr(rows, key)
            if key == "epsilon":
                out["rank_tolerance"] = fit.rank_tolerance
        out.update(max_inflation=fit.max_inflation, max_relative_std=fit.max_relative_std,
                   unexcited=None if fit.unexcited is None else fit.unexcited.value, estimator=fit.estimator.value,
                   robust_loss=fit.robust_loss.value, bounds=[list(b) for b in fit.bounds],
                   uncertainty=unc.method.value, bandwidth=unc.bandwidth, bandwidth_factor=unc.bandwidth_factor,
                   min_bandwidth=unc.min_bandwidth, bootstrap_replicates=unc.bootstrap_replicates, seed=unc.seed)
        return out
