"""The single-axis (lifted-wheel) identification of sec. 7: B_w and the wheel friction without load.

The paper fixes ``B_w`` from "a single axis parameter identification without ground contact"
(sec. 6.3, 7). With the vehicle on jacks each wheel obeys its row of eq. (16)-(17)::

    B_w beta_ddot + d_vw beta_dot + d_cw tanh(beta_dot / epsilon) = i_G M_mot        (per wheel)

which separates ``B_w`` from ``m_ch`` and ``C_ch`` (with ground contact it is nearly a combination
of them). The rows are built like all others: each continuous stretch filtered and differentiated
once (:func:`~agvdyn.identification.stretches.filtered_stretch`, parallel filtering of the
regressor entries and the torques), rows at the filter's edges, below the stiction threshold
(the chassis threshold as a wheel rate, ``stiction_threshold / r``) and within the guard dropped,
constant motor-torque offsets estimated alongside, the estimator and the uncertainty of the
settings. The friction without load is not the friction on the floor (wheel load, tyre
flexing): it is reported, the vehicle's ``d_vw``, ``d_cw`` come from the identification sequence.

A log is a lifted-wheel log when every labelled row carries the label ``lifted_wheel``, or when
the caller says so (``experiment_of(logs, "lifted-wheel")``, ``agvdyn identify --experiment lifted-wheel``).
:func:`identify_lifted` is the entry point, :func:`experiment_of` tells which one a set of logs needs.
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agvdyn.identification.estimators import Estimator
from agvdyn.identification.rows import labels_present
from agvdyn.identification.settings import OFFSET_NAMES, IdentificationSettings
from agvdyn.identification.stretches import filtered_stretch, log_source, min_stretch_rows, stretch_bounds
from agvdyn.identification.normal import RegressionData, RowIndex
from agvdyn.identification.result import UncertaintySummary
from agvdyn.identification.uncertainty import parameter_uncertainty
from agvdyn.platform import PARAMETER_UNITS, WHEELS, Geometry
from agvdyn.row_rules import row_mask
from agvdyn.time_base import stamp_interval

__all__ = ["LIFTED_LABEL", "EXPERIMENTS", "LIFTED_PARAMETERS", "LiftedWheelIdentification", "is_lifted",
           "lifted_experiment", "experiment_of", "mixed_experiments", "identify_lifted"]

#: Segment label of the single-axis experiment.
LIFTED_LABEL = "lifted_wheel"
#: Values of ``identify(..., experiment=)``: from the labels, the vehicle on the floor, or lifted wheels.
EXPERIMENTS = ("auto", "vehicle", "lifted-wheel")
#: Parameters of the lifted-wheel rows (regressor columns), in this order.
LIFTED_PARAMETERS = ("B_w", "d_vw", "d_cw")
_SIGNAL = {"B_w": 9, "d_vw": 13, "d_cw": 17}  # columns of agvdyn.dynamics.REGRESSOR_SIGNALS, + wheel index


def is_lifted(log: Any) -> bool:
    """Every labelled row of the log carries ``lifted_wheel`` (and some row is labelled)."""
    return labels_present(log) == {LIFTED_LABEL}


def lifted_experiment(logs: Sequence[Any], experiment: str | None) -> bool:
    """Whether ``logs`` are identified as a lifted-wheel experiment.

    ``experiment``: ``"lifted-wheel"``, ``"vehicle"``, or ``None`` / ``"auto"`` (from the labels:
    all logs lifted). Logs of both kinds in one call are an error naming them.
    """
    key = "auto" if experiment is None else str(experiment).strip().lower().replace("_", "-")
    if key not in EXPERIMENTS:
        raise ValueError(f"experiment {experiment!r}: expected one of {list(EXPERIMENTS)}")
    if key != "auto":
        return key == "lifted-wheel"
    flags = [is_lifted(log) for log in logs]
    if any(flags) and not all(flags):
        raise mixed_experiments([log_source(x) for x, f in zip(logs, flags) if f],
                                [log_source(x) for x, f in zip(logs, flags) if not f])
    return bool(flags) and all(flags)


def mixed_experiments(lifted: Sequence[str], ground: Sequence[str]) -> ValueError:
    """The error for lifted-wheel logs and vehicle logs in one identification (their sources)."""
    return ValueError(f"lifted-wheel logs {list(lifted)} and vehicle logs {list(ground)} in one identification: "
                      "identify the lifted-wheel log on its own and pass its B_w to the vehicle logs with "
                      "--fix B_w=VALUE")


def experiment_of(logs: Sequence[Any], experiment: str | None = "auto") -> str:
    """``"lifted-wheel"`` or ``"vehicle"``: which entry point identifies ``logs``
    (:func:`identify_lifted` or :func:`agvdyn.identification.identify`), as ``agvdyn identify`` decides.

    ``logs``: :class:`agvdyn.io.Log` or :class:`agvdyn.io.LogFile` (only the first one is read for an
    explicit experiment or a vehicle log; every one when the first is lifted, to refuse a mix).
    """
    first = logs[0].first() if hasattr(logs[0], "first") else logs[0]
    explicit = experiment is not None and str(experiment).strip().lower() != "auto"
    if lifted_experiment([first], experiment) and (explicit or len(logs) == 1):
        return "lifted-wheel"
    if not explicit and is_lifted(first):
        lifted_experiment([first] + [x.load() if hasattr(x, "load") else x for x in logs[1:]], experiment)
        return "lifted-wheel"
    return "vehicle"


@dataclass(frozen=True, eq=False)
class LiftedWheelIdentification:
    """Result of the lifted-wheel identification: ``B_w`` and the wheel friction without load.

    ``values``, ``std``: of :data:`LIFTED_PARAMETERS` (kg m^2, N m s/rad, N m; wheel side);
    ``offsets``: motor-torque offsets (motor side, N m); ``condition_number``:
    cond(Theta_w^T Theta_w) of the column-scaled regressor of the three parameters;
    ``residual_rms`` per wheel (N m, wheel side); ``rows``: rows used per wheel.
    """

    values: dict[str, float]
    std: dict[str, float]
    condition_number: float
    residual_rms: dict[str, float]
    rows: dict[str, int]
    n_samples: int
    offsets: dict[str, float]
    offsets_std: dict[str, float]
    settings: IdentificationSettings
    geometry: Geometry
    estimator: str
    uncertainty: UncertaintySummary | None = None
    sources: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    experiment = "lifted_wheel"

    @property
    def B_w(self) -> float:
        return self.values["B_w"]

    def ci95(self, name: str) -> tuple[float, float]:
        v, s = self.values[name], self.std[name]
        return (v - 1.959964 * s, v + 1.959964 * s)

    def _entries(self) -> dict[str, dict[str, Any]]:
        out = {}
        for n in LIFTED_PARAMETERS:
            entry: dict[str, Any] = {"value": self.values[n], "std": self.std[n], "ci95": list(self.ci95(n)),
                                     "unit": PARAMETER_UNITS[n]}
            if n != "B_w":
                entry["load"] = "none (wheels lifted): not the friction on the floor"
            out[n] = entry
        return out

    def to_json_dict(self) -> dict[str, Any]:
        """The summary printed by ``agvdyn identify --json`` for a lifted-wheel log."""
        return {
            "experiment": self.experiment,
            "parameters": self._entries(),
            "condition_number": self.condition_number,
            "fixed": [],
            "residual_rms": dict(self.residual_rms),
            "rows": dict(self.rows),
            "n_rows": int(sum(self.rows.values())),
            "n_samples": self.n_samples,
            "torque_offsets": {n: {"value": v, "std": self.offsets_std.get(n)} for n, v in self.offsets.items()},
            "estimator": self.estimator,
            "uncertainty": {} if self.uncertainty is None else self.uncertainty.to_dict(),
            "sources": list(self.sources),
            "notes": list(self.notes),
            "platform": self.geometry.to_dict(),
            "use": f"agvdyn identify VEHICLE_LOGS --fix B_w={self.B_w:.6g}",
        }

    def to_dict(self) -> dict[str, Any]:
        """The parameter file: ``parameters`` holds B_w and the unloaded wheel friction only (it is not a
        complete parameter file: pass B_w to the identification of the vehicle with ``--fix``)."""
        return {"experiment": self.experiment, "parameters": self._entries(),
                "condition_number": self.condition_number, "fixed": [], "platform": self.geometry.to_dict(),
                "residual_rms": dict(self.residual_rms), "rows": dict(self.rows),
                "torque_offsets": {n: {"value": v, "std": self.offsets_std.get(n)} for n, v in self.offsets.items()},
                "settings": self.settings.to_dict(), "sources": list(self.sources),
                "note": "single-axis identification without ground contact (sec. 7): use B_w with "
                        f"'agvdyn identify ... --fix B_w={self.B_w:.6g}'"}

    def write(self, path: str | os.PathLike) -> Path:
        """Write the result (YAML, or JSON by suffix) atomically."""
        import json

        import yaml

        from agvdyn._files import write_text_atomically

        path = Path(path)
        data = self.to_dict()
        text = json.dumps(data, indent=2) if path.suffix.lower() == ".json" else yaml.safe_dump(data, sort_keys=False)
        return write_text_atomically(path, text)


def _lifted_rows(log: Any, geometry: Geometry, settings: IdentificationSettings, recording0: int) -> tuple:
    """Rows of every wheel of one log: lists of regressor blocks (m, 3 + 4), right-hand sides i_G M,
    wheel index, recording and time step of each row; notes; the number of recordings used."""
    source = log_source(log)
    seg = getattr(log, "segments", None)
    labelled = None if seg is None else (np.asarray(seg) == LIFTED_LABEL)
    bounds, notes = stretch_bounds(log.t, log.alpha, log.beta, settings)
    notes = [f"{source}: {n}" for n in notes]
    min_rows = min_stretch_rows(settings, stamp_interval(np.asarray(log.t), source=f"{source}: column 't'"))
    threshold = settings.rows.stiction_threshold / geometry.r  # the chassis threshold as a wheel rate
    A, y, wheel, rec, step = [], [], [], [], []
    k = recording0
    for a, b in bounds:
        if b - a <= min_rows:
            notes.append(f"{source}: rows {a}..{b - 1} ({b - a} samples) skipped: too short for the zero-phase filter")
            continue
        st = filtered_stretch(geometry, log, a, b, settings)
        guard = settings.rows.guard_samples(settings.rows.stiction_guard, st.dt)
        usable = ~st.edge
        if labelled is not None:
            usable &= labelled[a:b]
        for i in range(4):
            keep = row_mask(st.beta_dot[:, i], threshold, guard) & usable
            if not keep.any():
                continue
            cols = [st.signals[keep, _SIGNAL[n] + i] for n in LIFTED_PARAMETERS]
            offsets = np.zeros((int(keep.sum()), 4))
            offsets[:, i] = geometry.i_G
            A.append(np.column_stack([*cols, offsets]))
            y.append(geometry.i_G * st.torque[keep, i])
            wheel.append(np.full(int(keep.sum()), i))
            rec.append(np.full(int(keep.sum()), k))
            step.append(np.flatnonzero(keep) + a)
        k += 1
    return A, y, wheel, rec, step, notes, k - recording0


def identify_lifted(logs: Sequence[Any], geometry: Geometry, *,
                    settings: IdentificationSettings = IdentificationSettings(),
                    estimator: Estimator | None = None) -> LiftedWheelIdentification:
    """B_w, d_vw, d_cw (without load) from lifted-wheel logs, per-wheel rows of eq. (16)-(17).

    Raises ValueError when no row is left (no lifted-wheel rows, or the wheels never turn faster
    than the stiction threshold).
    """
    A, y, wheel, rec, step, notes = [], [], [], [], [], []
    n_rec = 0
    for log in logs:
        a_, y_, w_, r_, s_, n_, k = _lifted_rows(log, geometry, settings, n_rec)
        A += a_
        y += y_
        wheel += w_
        rec += r_
        step += s_
        notes += n_
        n_rec += k
    if not A:
        raise ValueError("no usable lifted-wheel rows: the logs have no rows labelled 'lifted_wheel' with a wheel "
                         f"turning faster than {settings.rows.stiction_threshold / geometry.r:.3g} rad/s "
                         "(the stiction threshold as a wheel rate)")
    A_, y_ = np.concatenate(A), np.concatenate(y)
    wheel_, rec_, step_ = np.concatenate(wheel), np.concatenate(rec), np.concatenate(step)
    names = list(LIFTED_PARAMETERS) + (list(OFFSET_NAMES) if settings.fit.torque_offsets else [])
    if not settings.fit.torque_offsets:
        A_ = A_[:, :3]
    present = [j for j in range(A_.shape[1]) if np.any(A_[:, j] != 0)]
    A_, names = A_[:, present], [names[j] for j in present]
    est = estimator if estimator is not None else settings.fit.make_estimator()
    est = est.fit(A_, y_, groups=wheel_, names=names)
    index = RowIndex(wheel_.astype(np.int64), tuple(WHEELS), rec_.astype(np.int64), step_.astype(np.int64))
    u = settings.uncertainty
    unc = parameter_uncertainty(u.method, est, RegressionData.from_rows(A_, y_, index), bandwidth=u.bandwidth,
                                bandwidth_factor=u.bandwidth_factor, min_bandwidth=u.min_bandwidth,
                                replicates=u.bootstrap_replicates, seed=u.seed)
    sd = unc.std
    cols = A_[:, :3] / np.sqrt(np.einsum("ij,ij->j", A_[:, :3], A_[:, :3]))
    sv = np.linalg.svd(cols, compute_uv=False)
    residual = y_ - A_ @ est.coef_
    values = {n: float(v) for n, v in zip(names, est.coef_)}
    stds = {n: float(s) for n, s in zip(names, sd)}
    return LiftedWheelIdentification(
        values={n: values[n] for n in LIFTED_PARAMETERS}, std={n: stds[n] for n in LIFTED_PARAMETERS},
        condition_number=float((sv[0] / sv[-1]) ** 2),
        residual_rms={w: float(math.sqrt(np.mean(residual[wheel_ == i] ** 2))) if np.any(wheel_ == i) else math.nan
                      for i, w in enumerate(WHEELS)},
        rows={w: int(np.count_nonzero(wheel_ == i)) for i, w in enumerate(WHEELS)},
        n_samples=int(sum(len(log.t) for log in logs)),
        offsets={n: values[n] / 1.0 for n in OFFSET_NAMES if n in values},
        offsets_std={n: stds[n] for n in OFFSET_NAMES if n in stds},
        settings=settings, geometry=geometry, estimator=getattr(est, "name", "") or type(est).__name__,
        uncertainty=UncertaintySummary.of(unc.method.value, unc.details),
        sources=tuple(log_source(log) for log in logs), notes=tuple(notes))
