"""What the report's figures show, computed before anything is drawn (:mod:`agvdyn.plots` only
draws these): model torques of Fig. 5 and Fig. 6 on the kept rows, deviations of the parameters
from a reference, their correlation, the residuals with their autocorrelation, and the
data-quality timeline of each log.

Every function takes result objects and returns a frozen object of arrays and labels; numpy
only, no matplotlib.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from agvdyn.identification.correlation import masked_autocorrelation
from agvdyn.platform import PAPER_PARAMETERS, PAPER_STD, PARAMETER_NAMES
from agvdyn.segments_vocabulary import segment_mode

__all__ = ["TorquePanel", "TorqueFigure", "identification_torques", "validation_torques", "ParameterDeviations",
           "parameter_deviations", "CorrelationMatrix", "correlation_matrix", "ResidualPanel", "Residuals",
           "residuals", "residual_autocorrelation", "LogTimeline", "QualityTimeline", "quality_timeline",
           "COORDINATE_ORDER"]

#: Order of the generalized coordinates in the residual figure.
COORDINATE_ORDER = ("alpha_l", "alpha_r", "alpha_v", "x_ch", "y_ch", "gamma_ch")


@dataclass(frozen=True, eq=False)
class TorquePanel:
    """One segment and generalized coordinate: measured and model torque on every row of its runs
    (in time order), ``kept`` the rows the fit uses; ``key`` ``[file: ]segment:coordinate``."""

    key: str
    coordinate: str
    t: np.ndarray
    measured: np.ndarray
    model: np.ndarray
    kept: np.ndarray
    score: str | None = None


@dataclass(frozen=True, eq=False)
class TorqueFigure:
    """Fig. 5 or Fig. 6: a title and one panel per segment and coordinate with kept rows."""

    title: str
    panels: tuple[TorquePanel, ...]


def _panels(blocks, p, offsets, scores: Mapping[str, str]) -> tuple[TorquePanel, ...]:
    several = len({b.source for b in blocks}) > 1
    joined: dict[str, list] = {}
    for b in blocks:
        model = b.model_torque(p, offsets)
        for j, coord in enumerate(b.coordinates):
            key = (f"{b.source}: " if several else "") + f"{b.segment}:{coord}"
            entry = joined.setdefault(key, [coord, [], [], [], []])
            entry[1].append(b.t)
            entry[2].append(b.torque[:, j])
            entry[3].append(model[:, j])
            entry[4].append(b.keep[:, j])
    out = []
    for key, (coord, *arrays) in joined.items():
        t, measured, model, kept = (np.concatenate(a) for a in arrays)
        if not kept.any():
            continue  # e.g. the resting side while the other side steers
        order = np.argsort(t, kind="stable")
        out.append(TorquePanel(key, coord, t[order], measured[order], model[order], kept[order], scores.get(key)))
    return tuple(out)


def identification_torques(identification) -> TorqueFigure:
    """Fig. 5: measured and model torques (with the estimated motor-torque offsets, when any) of
    each identification segment, scored by the residual RMS."""
    scores = {k: f"residual RMS {v:.3g}" for k, v in identification.residual_rms.items()}
    return TorqueFigure("Identification experiment: generalized torques (cf. Fig. 5)",
                        _panels(identification.blocks, identification.parameters.to_vector(),
                                identification.offset_vector, scores))


def validation_torques(validation) -> TorqueFigure:
    """Fig. 6: measured and predicted torques of the validation log, scored by the NRMSE."""
    scores = {k: f"NRMSE {v:.3f}, without stiction {validation.nrmse_moving[k]:.3f}"
              for k, v in validation.nrmse.items()}
    return TorqueFigure("Validation experiment: generalized torques (cf. Fig. 6)",
                        _panels(validation.blocks, validation.parameters.to_vector(), None, scores))


@dataclass(frozen=True, eq=False)
class ParameterDeviations:
    """Deviation in percent of each estimated parameter from the reference, the half-width of its
    +-3 std bar (percent of the reference) and that of the reference's own std (NaN: none)."""

    names: tuple[str, ...]
    deviation_pct: np.ndarray
    bar_pct: np.ndarray
    reference_bar_pct: np.ndarray
    label: str


def parameter_deviations(identification, reference=PAPER_PARAMETERS, reference_std=PAPER_STD, *,
                         label: str = "Table 2") -> ParameterDeviations:
    """The estimated parameters against ``reference`` (a :class:`~agvdyn.platform.Parameters`)."""
    names = [n for n in PARAMETER_NAMES if n not in identification.fixed]
    ref = np.array([getattr(reference, n) for n in names])
    est = np.array([getattr(identification.parameters, n) for n in names])
    std = np.array([identification.std.get(n, np.nan) for n in names])
    ref_std = np.array([reference_std.get(n, np.nan) for n in names])
    return ParameterDeviations(tuple(names), 100 * (est / ref - 1), 300 * std / np.abs(ref),
                               300 * ref_std / np.abs(ref), label)


@dataclass(frozen=True, eq=False)
class CorrelationMatrix:
    """Correlation matrix of the estimates, their names, and the covariance method it is from."""

    names: tuple[str, ...]
    matrix: np.ndarray
    method: str


def correlation_matrix(identification) -> CorrelationMatrix:
    correlation = identification.correlation
    names = tuple(correlation.names)
    matrix = np.array(correlation.matrix, dtype=float).reshape(len(names), len(names))
    return CorrelationMatrix(names, matrix, identification.uncertainty.method or "")


@dataclass(frozen=True, eq=False)
class ResidualPanel:
    """One generalized coordinate: its residual traces ``(source index, t, residual)`` (NaN on the
    rows left out), the autocorrelation ``acf`` at lags ``0, dt, 2 dt, ...`` and the kept rows."""

    coordinate: str
    traces: tuple[tuple[int, np.ndarray, np.ndarray], ...]
    acf: np.ndarray
    rows: int


@dataclass(frozen=True, eq=False)
class Residuals:
    """The residual figure: one panel per coordinate, the sample time ``dt``, the HAC bandwidth in
    steps (None: none) and the files (trace colours)."""

    panels: tuple[ResidualPanel, ...]
    dt: float
    bandwidth: float | None
    sources: tuple[str, ...]


def residual_autocorrelation(identification, max_lag: int) -> dict[str, tuple[np.ndarray, int]]:
    """Autocorrelation of the residuals ``tau - H_k^T Theta p`` of the kept rows per generalized
    coordinate, lags ``0..max_lag`` samples: ``{coordinate: (acf, rows)}``, pooled over the blocks,
    only pairs of kept rows counting (:func:`agvdyn.identification.correlation.masked_autocorrelation`)."""
    p = identification.parameters.to_vector()
    offsets = identification.offset_vector
    pieces: dict[str, list] = {}
    for b in identification.blocks:
        r = b.torque - b.model_torque(p, offsets)
        for j, coord in enumerate(b.coordinates):
            pieces.setdefault(coord, []).append((r[:, j], b.keep[:, j]))
    out = {}
    for coord, runs in pieces.items():
        if any(k.any() for _, k in runs):
            out[coord] = masked_autocorrelation(runs, max_lag)
    return out


def residuals(identification, *, max_lag_s: float = 1.5) -> Residuals:
    """Residuals of the fit over time and their autocorrelation up to ``max_lag_s`` (at least twice
    the HAC bandwidth of the uncertainty, when it has one)."""
    p = identification.parameters.to_vector()
    offsets = identification.offset_vector
    blocks = identification.blocks
    dt = float(np.median(np.concatenate([np.diff(b.t) for b in blocks if b.t.size > 1]))) if blocks else 2e-3
    bandwidth = identification.uncertainty.bandwidth_steps
    max_lag = int(round(max(max_lag_s, 2.0 * (bandwidth or 0) * dt) / dt))
    acf = residual_autocorrelation(identification, max_lag)
    sources = sorted({b.source for b in blocks})
    panels = []
    for coord in (c for c in COORDINATE_ORDER if c in acf):
        traces = []
        for b in blocks:
            if coord not in b.coordinates:
                continue
            j = b.coordinates.index(coord)
            if not b.keep[:, j].any():
                continue
            r = b.torque[:, j] - b.model_torque(p, offsets)[:, j]
            traces.append((sources.index(b.source), b.t, np.where(b.keep[:, j], r, np.nan)))
        panels.append(ResidualPanel(coord, tuple(traces), *acf[coord]))
    return Residuals(tuple(panels), dt, bandwidth, tuple(sources))


@dataclass(frozen=True, eq=False)
class LogTimeline:
    """One log's lanes: labelled runs ``(name, start, end, mode label or "none", named)`` (``named``:
    long enough to write the name in), modes of the configuration ``(label, start, end)``, spans of
    kept rows, wheel-slip spans and cuts between continuous recordings (s)."""

    path: str
    t_start: float
    t_end: float
    labels: tuple[tuple[str, float, float, str, bool], ...]
    modes: tuple[tuple[str, float, float], ...]
    kept: tuple[tuple[float, float], ...]
    slip: tuple[tuple[float, float], ...]
    cuts: tuple[tuple[float, float], ...]


@dataclass(frozen=True, eq=False)
class QualityTimeline:
    """The data-quality figure: one timeline per log and the mode labels they show."""

    logs: tuple[LogTimeline, ...]
    modes_used: frozenset[str]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges of the True runs of a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _label_mode(name: str) -> str:
    try:
        return segment_mode(name) or "none"
    except KeyError:
        return "none"


def quality_timeline(files: Sequence, cuts: Sequence[Sequence[tuple[float, float]]] | None = None
                     ) -> QualityTimeline:
    """The timeline of each :class:`agvdyn.preflight.FileCheck`; ``cuts``: per file the time
    intervals (s) between two continuous stretches."""
    logs = []
    for k, check in enumerate(files):
        summary, rows = check.summary, check.rows
        labels = tuple((seg.name, seg.t_start, seg.t_end, _label_mode(seg.name),
                        seg.duration > 0.06 * max(summary.duration, 1e-9)) for seg in summary.segments)
        kept = tuple((float(blk.t[a]), float(blk.t[b - 1])) for blk in rows.blocks
                     for a, b in _runs(blk.keep.any(axis=1)))
        logs.append(LogTimeline(summary.path or "<log>", summary.t_start, summary.t_end, labels,
                                tuple(check.timeline), kept,
                                tuple((e.t_start, e.t_end) for e in rows.slip_events),
                                tuple(cuts[k]) if cuts is not None and k < len(cuts) else ()))
    return QualityTimeline(tuple(logs), frozenset(m for check in files for m, _, _ in check.timeline))
