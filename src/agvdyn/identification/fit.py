"""Regression stage of :func:`agvdyn.identification.identify`: the stacked system of eq. (22)
(rows, or pseudo-rows with its normal equations) with the fixed parameters to the right (eq. 24),
the rank and quality checks, the estimator, the uncertainty and the plausibility checks."""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from agvdyn.determinacy import std_from_covariance, std_from_information
from agvdyn.dynamics import N_P
from agvdyn.identifiability import triangular_factor
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.normal import (
    RegressionData,
    RowStatistics,
    RowStore,
    regression_data,
    row_statistics,
    stacked_regression_data,
)
from agvdyn.identification.plausibility import ImplausibleError, implausible_parameters
from agvdyn.identification.regression import (
    Dependency,
    Estimator,
    UnidentifiableError,
    column_norms,
    dependent_parameters,
    variance_inflation,
)
from agvdyn.identification.result import Identification, ParameterCorrelation, UncertaintySummary
from agvdyn.identification.rows import RowCounts
from agvdyn.identification.settings import DEFAULT_FIXED, OFFSET_NAMES, IdentificationSettings
from agvdyn.identification.slip import SlipEvent
from agvdyn.identification.uncertainty import parameter_uncertainty
from agvdyn.platform import PARAMETER_NAMES, Geometry, Parameters

__all__ = ["fit_blocks", "fit_regression", "check_fixed", "columns"]


def check_fixed(fixed: Mapping[str, float]) -> dict[str, float]:
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


def columns(fixed: Mapping[str, float], with_offsets: bool) -> tuple[list[str], list[str], list[int], np.ndarray]:
    """All column names, the free ones, their indices and the values of the fixed ones (eq. 24)."""
    names = list(PARAMETER_NAMES) + (list(OFFSET_NAMES) if with_offsets else [])
    free = [n for n in names if n not in fixed]
    p_fixed = np.zeros(len(names))
    for name, value in fixed.items():
        p_fixed[names.index(name)] = value
    return names, free, [names.index(n) for n in free], p_fixed


def fit_blocks(blocks: Sequence[EquationBlock], geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
               settings: IdentificationSettings = IdentificationSettings(), estimator: Estimator | None = None,
               stacked: bool = False, **account: Any) -> Identification:
    """Regression stage on equation blocks: by their normal equations (pseudo-rows, as
    :func:`identify`), or with ``stacked=True`` on all rows stacked in memory (the reference).
    ``account``: sources, notes, n_samples, rows, slip_events, slip_thresholds of the result."""
    fixed = check_fixed(fixed)
    blocks = tuple(blocks)
    _, _, idx_free, p_fixed = columns(fixed, settings.fit.torque_offsets)
    if stacked:
        data = stacked_regression_data(blocks, idx_free, p_fixed, offsets=settings.fit.torque_offsets)
    else:
        stats, store, names = RowStatistics(len(p_fixed)), RowStore(), {}
        row_statistics(blocks, stats, store, names, offsets=settings.fit.torque_offsets)
        data = regression_data(stats, names, idx_free, p_fixed, store)
    account.setdefault("n_samples", sum(b.t.size for b in blocks))
    return fit_regression(data, geometry, fixed=fixed, settings=settings, estimator=estimator, blocks=blocks,
                          **account)


def fit_regression(data: RegressionData, geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
                   settings: IdentificationSettings = IdentificationSettings(), estimator: Estimator | None = None,
                   blocks: Sequence[EquationBlock] = (), sources: Iterable[str] = (), notes: Iterable[str] = (),
                   n_samples: int = 0, rows: RowCounts | None = None, slip_events: Sequence[SlipEvent] = (),
                   slip_thresholds: Mapping[str, float] | None = None, workers: int = 1) -> Identification:
    """Regression stage: the stacked system of eq. (22) with the fixed parameters to the right
    (eq. 24), rank check naming what is not excited, scaled least squares (eq. 25), uncertainty
    (``workers`` threads), physical plausibility."""
    fixed = check_fixed(fixed)
    with_offsets = settings.fit.torque_offsets
    names, free, idx_free, p_fixed = columns(fixed, with_offsets)
    est = estimator if estimator is not None else settings.fit.make_estimator()
    if data.pseudo and getattr(est, "needs_rows", False):  # robust weighs single rows: read them back
        data = data.stacked()
    A1, y1 = data.A, data.y
    if data.n_rows <= len(free):
        raise UnidentifiableError(
            [Dependency(n, (), 0.0) for n in free],
            f"{data.n_rows} equation rows left after the stiction mask for {len(free)} parameters; ")
    report = settings.fit.reports_unexcited
    warnings: list[str] = []
    missing = dependent_parameters(A1, free, tolerance=settings.fit.rank_tolerance)
    unbounded: set[str] = set()
    if missing and not report:
        raise UnidentifiableError(missing)
    if missing:  # held at zero (bounded: their lower bound); they and their group get unbounded intervals
        unbounded, hold, warnings = _unexcited(missing, free, est)
        data = data.holding([free.index(n) for n in hold], np.array(list(hold.values())))
        free = [n for n in free if n not in hold]
        idx_free = [names.index(n) for n in free]
        for n, v in hold.items():
            p_fixed[names.index(n)] = v
        A1, y1 = data.A, data.y
    inflation = variance_inflation(A1)
    collinear = [Dependency(n, (), math.nan, inflation=float(v)) for n, v in zip(free, inflation)
                 if v > settings.fit.max_inflation and n in PARAMETER_NAMES]
    pseudo = {"group_rows": data.group_rows, "n_rows": data.n_rows} if data.pseudo else {}
    est = est.fit(A1, y1, groups=data.group, names=free, **pseudo)
    warnings += _collinear_warnings(collinear, data, est.coef_, free, settings.fit.max_inflation, refuse=not report)
    if data.pseudo and data.store is not None:  # eq. (25)'s sigma^2 from the rows themselves
        weights = np.ones(len(data.group_names))
        weights[data.group] = est.weights_
        sigma2 = float(data.group_rss(est.coef_) @ weights) / (data.n_rows - len(free))
        est.cov_, est.sigma2_ = est.cov_ * (sigma2 / est.sigma2_), sigma2
    u = settings.uncertainty
    unc = parameter_uncertainty(u.method, est, data, bandwidth=u.bandwidth, bandwidth_factor=u.bandwidth_factor,
                                min_bandwidth=u.min_bandwidth, replicates=u.bootstrap_replicates, seed=u.seed,
                                names=free, reported=PARAMETER_NAMES, workers=workers)
    sd_all, bad_variances = std_from_covariance(unc.cov, free)
    warnings += list(unc.warnings) + bad_variances
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
    all_std = {n: (math.inf if n in unbounded else v) for n, v in zip(free, sd_all.tolist())}
    std = {n: v for n, v in all_std.items() if n in PARAMETER_NAMES}
    std_classic = {n: (math.inf if n in unbounded else float(v)) for n, v in zip(free, est.std_)
                   if n in PARAMETER_NAMES}
    correlation = _correlation(unc.cov, free, unbounded)
    residual_rms = data.residual_rms(est.coef_)
    for n in unbounded - set(free):  # held parameters
        all_std[n] = math.inf
        if n in PARAMETER_NAMES:
            std[n] = std_classic[n] = math.inf
    if settings.fit.plausibility:
        refused, implausible = implausible_parameters({n: float(v) for n, v in zip(free, est.coef_)
                                                       if n in PARAMETER_NAMES and n not in unbounded}, std)
        if refused:
            raise ImplausibleError(refused, None, "")
        warnings += implausible
    noisy = [Dependency(n, (), math.nan, relative_std=float(sd / abs(v)))
             for n, v, sd in zip(free, est.coef_, sd_all)
             if n in PARAMETER_NAMES and n not in unbounded and sd > settings.fit.max_relative_std * abs(v)]
    if noisy and not report:
        raise UnidentifiableError(noisy, f"weakly excited data (standard deviation above "
                                         f"{100 * settings.fit.max_relative_std:g} % of the value): ")
    warnings += [f"weakly excited: {d.describe()}" for d in noisy]
    return Identification(
        parameters=Parameters.from_vector(p), std=std, fixed=tuple(n for n in PARAMETER_NAMES if n in fixed),
        condition_number=cond, condition_number_unscaled=cond_unscaled,
        condition_number_with_offsets=cond_with_offsets,
        residual_rms=residual_rms, n_rows=int(data.n_rows), n_samples=int(n_samples), blocks=tuple(blocks), settings=settings, geometry=geometry, sources=tuple(sources), notes=tuple(notes),
        estimator=getattr(est, "name", "") or type(est).__name__,
        std_classic=std_classic,
        correlation=ParameterCorrelation(tuple(correlation["names"]), tuple(map(tuple, correlation["matrix"]))),
        uncertainty=UncertaintySummary.of(unc.method.value, unc.details, None if unc.dof is None else {
            n: (float(v) if math.isfinite(v) else None) for n, v in zip(free, unc.dof) if n in PARAMETER_NAMES}),
        quantiles={n: float(q) for n, q in zip(free, unc.quantile()) if n in PARAMETER_NAMES},
        active_bounds=tuple(getattr(est, "active_", ())),
        downweighted_rows=int(np.count_nonzero(getattr(est, "downweighted_", []))),
        offsets={} if offsets is None else dict(zip(OFFSET_NAMES, offsets.tolist())),
        offsets_std={n: all_std[n] for n in OFFSET_NAMES if n in all_std},
        rows=rows if rows is not None else RowCounts(), slip_events=tuple(slip_events),
        slip_thresholds=dict(slip_thresholds or {}), warnings=tuple(warnings))


#: A parameter whose column is nearly a combination of the others (variance inflation above
#: ``max_inflation``) is still identified when the data carry enough information on it: its std
#: predicted from the regressor with the planner's noise level of each coordinate (or the residual
#: RMS where larger) at most this share of its value. Car-like turns next to fast rotation
#: determine B_w so (``agvdyn simulate car-like``, docs/planning.md); noise-free data do not pass
#: for determined, their predicted std uses the nominal noise.
COLLINEAR_RELATIVE_STD = 0.1


def predicted_relative_std(data: RegressionData, coef: np.ndarray, names: Sequence[str]) -> dict[str, float]:
    """Std of each free parameter relative to ``coef`` predicted from the information of the rows:
    per coordinate the larger of the planner's noise level (:class:`NoiseLevels`, effective 2 ms
    row noise with the HAC inflation of the simulator) and the residual RMS (inf where singular)."""
    from agvdyn.trajectories.planner.settings import NoiseLevels

    nominal = NoiseLevels()
    measured: dict[str, float] = {}
    for key, rms in data.residual_rms(coef).items():
        coord = key.rsplit(":", 1)[-1]
        measured[coord] = max(measured.get(coord, 0.0), rms)
    info = np.zeros((len(names), len(names)))
    for g, coord in enumerate(data.group_names):
        rows = data.A[data.group == g]
        level = max(getattr(nominal, coord, 0.0), measured.get(coord, 0.0))
        if rows.size and level > 0:
            info += rows.T @ rows / level**2
    std = std_from_information(info)[0]  # inf where the rows do not determine the parameter
    with np.errstate(divide="ignore"):
        return {n: float(s / abs(v)) if v else math.inf for n, s, v in zip(names, std, coef)}


def _collinear_warnings(collinear: Sequence[Dependency], data: RegressionData, coef: np.ndarray,
                        free: Sequence[str], max_inflation: float, *, refuse: bool) -> list[str]:
    """Warnings on the poorly conditioned parameters; with ``refuse``, :class:`UnidentifiableError`
    naming them when any of them has a predicted std above ``COLLINEAR_RELATIVE_STD`` of its value
    (those with their predicted std, the others of the group with their variance inflation)."""
    if not collinear:
        return []
    rel = predicted_relative_std(data, coef, free)
    weak = {d.name for d in collinear if not rel[d.name] <= COLLINEAR_RELATIVE_STD}
    if weak and refuse:
        named = [Dependency(d.name, (), math.nan, inflation=d.inflation,
                            relative_std=rel[d.name] if d.name in weak else math.nan) for d in collinear]
        hint = ("; B_w needs fast rotation and tight car-like turns with large yaw accelerations next to the "
                "identification sequence, agvdyn simulate car-like" if "B_w" in weak else "")
        raise UnidentifiableError(named, f"poorly conditioned data (variance inflation above {max_inflation:g} "
                                         f"and a predicted standard deviation above "
                                         f"{100 * COLLINEAR_RELATIVE_STD:g} % of the value{hint}): ")
    return [f"poorly conditioned: {d.describe()}"
            + ("" if d.name in weak else f"; determined by the data: predicted std {100 * rel[d.name]:.2g} % of "
               "its value, sensitive to model errors")
            + (_BW_ON_THE_FLOOR if d.name == "B_w" and d.name not in weak else "")
            for d in collinear]


#: What B_w from motion on the floor is (docs/planning.md, "B_w from car-like motion").
_BW_ON_THE_FLOOR = ("; on the floor B_w is the inertia seen at the contact points: wheel, gear and motor plus "
                    "m r^2 of any mass over the contact point (steering units), and tyre compliance biases it "
                    "(about -20 % with the simulator's tyres): compare with the lifted-wheel test")


def _unexcited(missing: Sequence[Dependency], free: Sequence[str], est: Estimator
               ) -> tuple[set[str], dict[str, float], list[str]]:
    """For ``unexcited="report"``: the parameters whose interval is unbounded (not excited, or
    excited only together with others), the values the unexcited ones are held at (zero, or the
    lower bound of ``bounded``) and the warnings naming them."""
    from agvdyn.identification.estimators import PHYSICAL_BOUNDS, Bounded

    bounds = {**PHYSICAL_BOUNDS, **dict(est.bounds or {})} if isinstance(est, Bounded) else {}
    hold = {d.name: max(0.0, float(bounds.get(d.name, (0.0, math.inf))[0])) for d in missing}
    unbounded = set(hold)
    warnings = []
    for d in missing:
        warnings.append(f"not identified, 95 % interval unbounded (value held at {hold[d.name]:g}): {d.describe()}")
        unbounded |= set(d.combination_of)
    for rep in sorted(unbounded - set(hold), key=list(free).index):
        group = [d.name for d in missing if rep in d.combination_of]
        warnings.append(f"{rep} carries the combination of {rep} with {', '.join(group)} (their columns are "
                        "dependent in these data): its value is the group's, its 95 % interval is unbounded")
    return unbounded, hold, warnings


def _correlation(cov: np.ndarray, names: Sequence[str], unbounded: set[str] = frozenset()) -> dict[str, Any]:
    """Correlation matrix of the estimated parameters (offsets left out; 0 for unbounded ones)."""
    keep = [i for i, n in enumerate(names) if n in PARAMETER_NAMES]
    c = cov[np.ix_(keep, keep)].copy()
    for k, i in enumerate(keep):
        if names[i] in unbounded:
            c[k, :] = c[:, k] = 0.0
    d = std_from_covariance(c)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        r = c / np.outer(d, d)
    r[~np.isfinite(r)] = 0.0
    np.fill_diagonal(r, 1.0)
    return {"names": [names[i] for i in keep], "matrix": r.round(6).tolist()}


