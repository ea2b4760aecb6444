"""Entry point :func:`identify`: logs -> rows (stretches filtered once, rows classified) -> regression."""
from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from agvdyn.dynamics import N_P
from agvdyn.identifiability import triangular_factor
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.plausibility import (
    ImplausibleError,
    diagnose_signs,
    encoder_sign_candidates,
    pick_sign_candidate,
    implausible_parameters,
    overall_rms,
)
from agvdyn.identification.regression import (
    Dependency,
    Estimator,
    UnidentifiableError,
    column_norms,
    dependent_parameters,
    stacked_rows,
    variance_inflation,
)
from agvdyn.identification.uncertainty import parameter_uncertainty
from agvdyn.identification.result import Identification
from agvdyn.identification.rows import RowCounts, log_rows
from agvdyn.identification.settings import DEFAULT_FIXED, OFFSET_NAMES, IdentificationSettings
from agvdyn.identification.slip import SlipEvent
from agvdyn.platform import PARAMETER_NAMES, PROTOTYPE, Geometry, Parameters, read_platform

__all__ = ["identify", "fit_blocks", "load_logs", "platform_for"]


def load_logs(logs: Any, *, mapping: Any = None, platform: Geometry | str | os.PathLike | None = None,
              stop_tolerance: float | None = None) -> list[Any]:
    """Logs as :class:`agvdyn.io.Log` objects: paths are loaded and checked with
    ``agvdyn.io.load_log(path, mapping, platform)`` (mapping: for tables and bags not in our
    schema), Log objects are passed through."""
    from agvdyn.io import STOP_TOLERANCE, load_log

    if isinstance(logs, (str, os.PathLike)) or hasattr(logs, "alpha"):
        logs = [logs]
    tol = STOP_TOLERANCE if stop_tolerance is None else stop_tolerance
    out = [load_log(x, mapping, platform, stop_tolerance=tol) if isinstance(x, (str, os.PathLike)) else x for x in logs]
    if not out:
        raise ValueError("no logs given: expected at least one log")
    return out


def platform_for(logs: Sequence[Any], platform: Geometry | str | os.PathLike | None) -> Geometry:
    """The geometry to use: the one given, else the ``platform`` of the first log's sidecar, else PROTOTYPE."""
    from agvdyn.io import sidecar_platform

    if isinstance(platform, Geometry):
        return platform
    if platform is not None:
        return read_platform(platform)
    for log in logs:
        if getattr(log, "sidecar", None):
            found = sidecar_platform(log)
            if found is not None:
                return found
    return PROTOTYPE


def _check_fixed(fixed: Mapping[str, float]) -> dict[str, float]:
    out = {}
    for name, value in fixed.items():
        if name not in PARAMETER_NAMES:
            raise ValueError(f"fixed parameter {name!r}: expected one of {list(PARAMETER_NAMES)}")
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"fixed parameter {name}={value!r}: expected a finite number")
        out[name] = float(value)
    if len(out) == len(PARAMETER_NAMES):
        raise ValueError("every parameter is fixed: nothing to identify")
    return out


def _residual_rms(blocks: Sequence[EquationBlock], p: np.ndarray, offsets: np.ndarray | None = None
                  ) -> dict[str, float]:
    """RMS of tau - Theta p over the kept rows per "segment:coordinate" (runs of equal name pooled);
    coordinates with no kept row (e.g. the resting side while the other one steers) are left out."""
    sums: dict[str, list[float]] = {}
    for b in blocks:
        r = b.torque - b.model_torque(p, offsets)
        for j, coord in enumerate(b.coordinates):
            sel = r[b.keep[:, j], j]
            if sel.size:
                acc = sums.setdefault(f"{b.segment}:{coord}", [0.0, 0])
                acc[0] += float(sel @ sel)
                acc[1] += sel.size
    return {k: math.sqrt(s / n) for k, (s, n) in sums.items()}


def fit_blocks(blocks: Sequence[EquationBlock], geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
               settings: IdentificationSettings = IdentificationSettings(), estimator: Estimator | None = None,
               sources: Iterable[str] = (), notes: Iterable[str] = (), n_samples: int | None = None,
               rows: RowCounts | None = None, slip_events: Sequence[SlipEvent] = (),
               slip_thresholds: Mapping[str, float] | None = None) -> Identification:
    """Regression stage: stack the blocks (eq. 22), fixed parameters to the right (eq. 24), rank
    check naming what is not excited, scaled least squares (eq. 25), physical plausibility."""
    fixed = _check_fixed(fixed)
    blocks = tuple(blocks)
    with_offsets = settings.torque_offsets
    A, y, index = stacked_rows(blocks, offsets=with_offsets)
    names = list(PARAMETER_NAMES) + (list(OFFSET_NAMES) if with_offsets else [])
    free = [n for n in names if n not in fixed]
    idx_free = [names.index(n) for n in free]
    p_fixed = np.zeros(len(names))
    for name, value in fixed.items():
        p_fixed[names.index(name)] = value
    if A.shape[0] <= len(free):
        raise UnidentifiableError(
            [Dependency(n, (), 0.0) for n in free],
            f"{A.shape[0]} equation rows left after the stiction mask for {len(free)} parameters; ")
    y1 = y - A @ p_fixed  # eq. (24)
    A1 = A[:, idx_free]
    missing = dependent_parameters(A1, free, tolerance=settings.rank_tolerance)
    if missing:
        raise UnidentifiableError(missing)
    inflation = variance_inflation(A1)
    collinear = [Dependency(n, (), math.nan, inflation=float(v)) for n, v in zip(free, inflation)
                 if v > settings.max_inflation and n in PARAMETER_NAMES]
    if collinear:
        raise UnidentifiableError(collinear, f"poorly conditioned data (variance inflation above "
                                             f"{settings.max_inflation:g}): ")
    est = (estimator if estimator is not None else settings.make_estimator()).fit(A1, y1, groups=index.group,
                                                                               names=free)
    unc = parameter_uncertainty(settings.uncertainty, est, A1, y1, index, bandwidth=settings.bandwidth,
                                bandwidth_factor=settings.bandwidth_factor, min_bandwidth=settings.min_bandwidth,
                                replicates=settings.bootstrap_replicates, seed=settings.seed)
    sd_all = unc.std
    # cond(Theta_1,w^T Theta_1,w) of the paper's parameters alone (eq. 25); the nuisance offset
    # columns are reported separately
    param_cols = [i for i, n in enumerate(free) if n in PARAMETER_NAMES]
    if len(param_cols) < len(free):
        cond_with_offsets = float(est.condition_number_)
        R = triangular_factor(A1[:, param_cols] / column_norms(A1[:, param_cols]))
        sv = np.linalg.svd(R, compute_uv=False)
        cond = float((sv[0] / sv[-1]) ** 2)
        sv_raw = np.linalg.svd(R * column_norms(A1[:, param_cols]), compute_uv=False)
        cond_unscaled = float((sv_raw[0] / sv_raw[-1]) ** 2)
    else:
        cond = float(est.condition_number_)
        cond_unscaled = float(getattr(est, "condition_number_unscaled_", float("nan")))
        cond_with_offsets = float("nan")
    theta = p_fixed.copy()
    theta[idx_free] = est.coef_
    p = theta[:N_P]
    offsets = theta[N_P:] if with_offsets else None
    all_std = dict(zip(free, sd_all.tolist()))
    std = {n: v for n, v in all_std.items() if n in PARAMETER_NAMES}
    std_classic = {n: float(v) for n, v in zip(free, est.std_) if n in PARAMETER_NAMES}
    correlation = _correlation(unc.cov, free)
    residual_rms = _residual_rms(blocks, p, offsets)
    warnings: list[str] = []
    if settings.plausibility:
        refused, warnings = implausible_parameters({n: float(v) for n, v in zip(free, est.coef_)
                                                    if n in PARAMETER_NAMES}, std)
        if refused:
            raise ImplausibleError(refused, None, "")
    noisy = [Dependency(n, (), math.nan, relative_std=float(sd / abs(v)))
             for n, v, sd in zip(free, est.coef_, sd_all)
             if n in PARAMETER_NAMES and sd > settings.max_relative_std * abs(v)]
    if noisy:
        raise UnidentifiableError(noisy, f"weakly excited data (standard deviation above "
                                         f"{100 * settings.max_relative_std:g} % of the value): ")
    return Identification(
        parameters=Parameters.from_vector(p), std=std, fixed=tuple(n for n in PARAMETER_NAMES if n in fixed),
        condition_number=cond, condition_number_unscaled=cond_unscaled,
        condition_number_with_offsets=cond_with_offsets,
        residual_rms=residual_rms, n_rows=int(A.shape[0]),
        n_samples=int(n_samples if n_samples is not None else sum(b.t.size for b in blocks)),
        blocks=blocks, settings=settings, geometry=geometry, sources=tuple(sources), notes=tuple(notes),
        estimator=getattr(est, "name", "") or type(est).__name__,
        std_classic=std_classic, correlation=correlation,
        uncertainty={"method": unc.method.value, **unc.details},
        active_bounds=tuple(getattr(est, "active_", ())),
        downweighted_rows=int(np.count_nonzero(getattr(est, "downweighted_", []))),
        offsets={} if offsets is None else dict(zip(OFFSET_NAMES, offsets.tolist())),
        offsets_std={n: all_std[n] for n in OFFSET_NAMES if n in all_std},
        rows=rows if rows is not None else RowCounts(), slip_events=tuple(slip_events),
        slip_thresholds=dict(slip_thresholds or {}), warnings=tuple(warnings))


def _correlation(cov: np.ndarray, names: Sequence[str]) -> dict[str, Any]:
    """Correlation matrix of the estimated parameters (offsets left out)."""
    keep = [i for i, n in enumerate(names) if n in PARAMETER_NAMES]
    c = cov[np.ix_(keep, keep)]
    d = np.sqrt(np.maximum(np.diag(c), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = c / np.outer(d, d)
    r[~np.isfinite(r)] = 0.0
    np.fill_diagonal(r, 1.0)
    return {"names": [names[i] for i in keep], "matrix": r.round(6).tolist()}


def identify(logs: Any, platform: Geometry | str | os.PathLike | None = None, *,
             fixed: Mapping[str, float] = DEFAULT_FIXED,
             settings: IdentificationSettings = IdentificationSettings(),
             estimator: Estimator | None = None, experiment: str | None = None) -> Identification:
    """Identify the dynamic parameters p (eq. 18) from one or more logs, eq. (22)-(25).

    Lifted-wheel logs (every labelled row ``lifted_wheel``, or ``experiment="lifted-wheel"``) give
    B_w and the unloaded wheel friction instead: a :class:`~agvdyn.identification.lifted.LiftedWheelIdentification`.

    Parameters
    ----------
    logs : path, Log, or a sequence of them (paths are read with :func:`agvdyn.io.load_log`).
    platform : Geometry or platform file; default the sidecar's platform, else the prototype.
    fixed : parameters taken as known (eq. 24), default ``{"B_w": 0.121}``.
    settings : :class:`IdentificationSettings`.
    estimator : an :class:`Estimator`, default :class:`LeastSquares`.
    experiment : ``"auto"``/None (from the labels), ``"vehicle"`` or ``"lifted-wheel"``.

    Raises
    ------
    UnidentifiableError
        When the data do not excite some free parameter (message names it and the experiment
        that would excite it).
    ImplausibleError
        A mass, inertia or friction came out negative; the message names the likely sign mistake.
    SignConventionError
        The encoders contradict the rolling constraints unless a sign is changed (named).
    """
    logs = load_logs(logs)
    geometry = platform_for(logs, platform)
    from agvdyn.identification.lifted import identify_lifted, lifted_experiment

    if lifted_experiment(logs, experiment):
        return identify_lifted(logs, geometry, settings=settings, estimator=estimator)
    _check_segments_present(logs, settings)
    try:
        return _identify_loaded(logs, geometry, fixed, settings, estimator)
    except (UnidentifiableError, ImplausibleError) as exc:
        # the diagnosis compares values and residuals only: the classic covariance is enough
        lenient = dataclasses.replace(settings, plausibility=False, uncertainty="classic")
        candidates = encoder_sign_candidates(logs, geometry, settings)  # the rolling constraints tell first
        if candidates:
            mistake = pick_sign_candidate(
                logs, candidates, lambda flipped: _identify_loaded(flipped, geometry, fixed, lenient, estimator))
            raise mistake from None
        if isinstance(exc, UnidentifiableError):
            raise
        unchecked = _identify_loaded(logs, geometry, fixed, dataclasses.replace(lenient, max_relative_std=math.inf),
                                     estimator)
        cause, detail = diagnose_signs(
            logs, lambda flipped: _identify_loaded(flipped, geometry, fixed, lenient, estimator), overall_rms(unchecked))
        raise ImplausibleError(exc.implausible, cause, detail) from None


def _identify_loaded(logs: Sequence[Any], geometry: Geometry, fixed: Mapping[str, float],
                     settings: IdentificationSettings, estimator: Estimator | None) -> Identification:
    blocks: list[EquationBlock] = []
    notes: list[str] = []
    counts = RowCounts()
    events: list[SlipEvent] = []
    thresholds: dict[str, float] = {}
    for log in logs:
        rows = log_rows(log, geometry, settings)
        blocks += rows.blocks
        notes += rows.notes
        counts.add(rows.counts)
        events += rows.slip_events
        thresholds[rows.source] = rows.slip_threshold
    if not blocks:
        raise ValueError(
            "no usable rows: the logs contain no samples in a motion mode of the model "
            f"(segments used: {', '.join(settings.segments) if settings.segments else 'all'}; rows: {counts.to_dict()})")
    sources = [str(getattr(log, "path", None) or "<log>") for log in logs]
    return fit_blocks(blocks, geometry, fixed=fixed, settings=settings, estimator=estimator, sources=sources,
                      notes=notes, n_samples=sum(len(log.t) for log in logs), rows=counts, slip_events=events,
                      slip_thresholds=thresholds)


def _check_segments_present(logs: Sequence[Any], settings: IdentificationSettings) -> None:
    """``settings.segments`` must name labels some log carries; else an error listing the ones present."""
    if settings.segments is None:
        return
    present = sorted({str(x) for log in logs if getattr(log, "segments", None) is not None
                      for x in np.unique(log.segments) if str(x)})
    missing = [s for s in settings.segments if s not in present]
    if missing:
        raise ValueError(f"segments {missing} are not in the logs: the logs carry the labels "
                         f"{present or 'none (no segment column)'}")
