"""Regression stage of :func:`agvdyn.identification.identify`: the stacked system of eq. (22)
(rows, or pseudo-rows with its normal equations) with the fixed parameters to the right (eq. 24),
in steps that each take and return a typed object:

    RegressionData -> check_excitation (rank, held parameters, variance inflation; :mod:`.excitation`)
    -> ExcitationCheck -> estimate (the estimator, eq. 25's sigma^2 from the stored rows) -> Estimate
    -> fit_uncertainty (covariance, std, correlation, condition numbers) -> FitUncertainty
    -> check_plausibility (impossible values refused, weak excitation) -> warnings
    -> assemble -> Identification

:func:`fit_regression` runs them; :func:`fit_blocks` feeds them equation blocks.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.determinacy import std_from_covariance
from agvdyn.dynamics import N_P
from agvdyn.identification.account import RowAccount
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.estimators import scaled_condition
from agvdyn.identification.excitation import (
    COLLINEAR_RELATIVE_STD,
    ExcitationCheck,
    check_excitation,
    collinear_warnings,
)
from agvdyn.identification.normal import (
    RegressionData,
    RowStatistics,
    RowStore,
    regression_data,
    row_statistics,
    stacked_regression_data,
)
from agvdyn.identification.model_fit import (
    breakaway_warnings,
    extension_estimates,
    hold_unobservable,
    unsupported_breakaway,
    noisy_extensions,
    residual_sums,
    tie_unsupported,
    with_unobservable,
)
from agvdyn.identification.model_rows import resolved_model
from agvdyn.identification.plausibility import ImplausibleError, implausible_parameters
from agvdyn.identification.regression import Dependency, Estimator, UnidentifiableError
from agvdyn.identification.result import Identification, ParameterCorrelation, UncertaintySummary
from agvdyn.identification.settings import DEFAULT_FIXED, OFFSET_NAMES, IdentificationSettings
from agvdyn.identification.uncertainty import parameter_uncertainty
from agvdyn.model_spec import BREAKAWAY_NAMES, CENTRE_NAMES, EXTRA_NAMES, FRICTION_GROUPS, PAPER_MODEL, ModelSpec
from agvdyn.platform import PARAMETER_NAMES, Geometry, Parameters

__all__ = ["fit_blocks", "fit_regression", "normal_equations", "check_fixed", "columns", "Estimate", "FitUncertainty", "estimate",
           "fit_uncertainty", "check_plausibility", "assemble", "COLLINEAR_RELATIVE_STD"]


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


def columns(fixed: Mapping[str, float], with_offsets: bool, model: ModelSpec = PAPER_MODEL
            ) -> tuple[list[str], list[str], list[int], np.ndarray]:
    """All column names (the paper's parameters, the offsets ``with_offsets``, the ``model``'s columns
    ``linear_names``), the free ones, their indices and the values of the fixed ones (eq. 24)."""
    names = list(PARAMETER_NAMES) + (list(OFFSET_NAMES) if with_offsets else []) + list(model.linear_names)
    free = [n for n in names if n not in fixed]
    p_fixed = np.zeros(len(names))
    for name, value in fixed.items():
        p_fixed[names.index(name)] = value
    return names, free, [names.index(n) for n in free], p_fixed


def fit_blocks(blocks: Sequence[EquationBlock], geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
               settings: IdentificationSettings = IdentificationSettings(), estimator: Estimator | None = None,
               stacked: bool = False, model: ModelSpec = PAPER_MODEL, **account: Any) -> Identification:
    """Regression stage on equation blocks: by their normal equations (pseudo-rows, as
    :func:`identify`), or with ``stacked=True`` on all rows stacked in memory (the reference the
    tests compare with). ``account``: fields of the result's :class:`RowAccount` (sources, notes,
    n_samples, counts, slip_events, slip_thresholds). ``model``: the resolved model whose columns the
    blocks carry (``EquationBlock.model_regressor``)."""
    fixed = check_fixed(fixed)
    blocks = tuple(blocks)
    model = _model_of(blocks, model)
    _, _, idx_free, p_fixed = columns(fixed, settings.fit.torque_offsets, model)
    if stacked:
        data = stacked_regression_data(blocks, idx_free, p_fixed, offsets=settings.fit.torque_offsets)
    else:
        data = normal_equations(blocks, idx_free, p_fixed, offsets=settings.fit.torque_offsets)
    account.setdefault("n_samples", sum(b.t.size for b in blocks))
    return fit_regression(data, geometry, fixed=fixed, settings=settings, estimator=estimator,
                          account=RowAccount(blocks=list(blocks), **account), model=model)


def _model_of(blocks: Sequence[EquationBlock], model: ModelSpec) -> ModelSpec:
    """The resolved ``model``, checked against the columns the blocks carry."""
    model = resolved_model(model)
    want = len(model.linear_names)
    have = {0 if b.model_regressor is None else b.model_regressor.shape[2] for b in blocks}
    if have - {want}:
        raise ValueError(f"equation blocks with {sorted(have)} model columns for model {model.label} "
                         f"({want}: {list(model.linear_names)}): make the rows with the same model")
    return model


def normal_equations(blocks: Sequence[EquationBlock], free: Sequence[int], theta_fixed: np.ndarray, *,
                     offsets: bool) -> RegressionData:
    """The kept rows of ``blocks`` as pseudo-rows with their normal equations (:mod:`.normal`), the
    rows themselves in a store (close it with ``data.store.close()``)."""
    stats, store, names = RowStatistics(len(theta_fixed)), RowStore(), {}
    row_statistics(blocks, stats, store, names, offsets=offsets)
    return regression_data(stats, names, free, theta_fixed, store)


def fit_regression(data: RegressionData, geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
                   settings: IdentificationSettings = IdentificationSettings(), estimator: Estimator | None = None,
                   account: RowAccount | None = None, workers: int = 1, model: ModelSpec = PAPER_MODEL
                   ) -> Identification:
    """Regression stage: the stacked system of eq. (22) with the fixed parameters to the right
    (eq. 24), rank check naming what is not excited, scaled least squares (eq. 25), uncertainty
    (``workers`` threads), physical plausibility; ``account``: the rows' account for the result;
    ``model``: the resolved model whose columns ``data`` has after the paper's and the offsets."""
    fixed = check_fixed(fixed)
    model = resolved_model(model)
    free = columns(fixed, settings.fit.torque_offsets, model)[1]
    est = estimator if estimator is not None else settings.fit.make_estimator()
    account = account if account is not None else RowAccount()
    data, free, unseen = hold_unobservable(data, free, model)
    unsupported = unsupported_breakaway(model, account.counts.stribeck_support)
    data, free = tie_unsupported(data, free, unsupported)  # at the paper's law d_s = d_c
    check = with_unobservable(check_excitation(data, free, est, settings), unseen)
    fitted = estimate(check, est, settings)
    unc = fit_uncertainty(check, fitted, settings, workers)
    if unsupported:  # not determined: unbounded, left out of the plausibility checks
        check = dataclasses.replace(check, unbounded=check.unbounded | frozenset(unsupported),
                                    warnings=check.warnings + tuple(unsupported.values()))
        unc.std.update(dict.fromkeys(unsupported, math.inf))
    warnings = check_plausibility(check, fitted, unc, settings, geometry)
    return assemble(check, fitted, unc, warnings, fixed=fixed, settings=settings, geometry=geometry,
                    account=account, model=model)


@dataclass(frozen=True, eq=False)
class Estimate:
    """Step 2: the fitted estimator (``coef_`` of the free parameters of the check, ``cov_`` and
    ``sigma2_`` with eq. (25)'s sigma^2 from the stored rows) and the warnings on poorly conditioned
    parameters the data still determine."""

    estimator: Estimator
    warnings: tuple[str, ...]

    @property
    def coef(self) -> np.ndarray:
        return self.estimator.coef_


def estimate(check: ExcitationCheck, estimator: Estimator, settings: IdentificationSettings) -> Estimate:
    """Step 2: the estimator on the check's data; :class:`UnidentifiableError` for poorly conditioned
    parameters the data do not determine (unless ``unexcited="report"``)."""
    data, free = check.data, list(check.free)
    pseudo = {"group_rows": data.group_rows, "n_rows": data.n_rows} if data.pseudo else {}
    est = estimator.fit(data.A, data.y, groups=data.group, names=free, **pseudo)
    warnings = collinear_warnings(check.collinear, data, est.coef_, free, settings.fit.max_inflation,
                                  refuse=not settings.fit.reports_unexcited)
    if data.pseudo and data.store is not None:  # eq. (25)'s sigma^2 from the rows themselves
        weights = np.ones(len(data.group_names))
        weights[data.group] = est.weights_
        sigma2 = float(data.group_rss(est.coef_) @ weights) / (data.n_rows - len(free))
        est.cov_, est.sigma2_ = est.cov_ * (sigma2 / est.sigma2_), sigma2
    return Estimate(est, tuple(warnings))


@dataclass(frozen=True, eq=False)
class FitUncertainty:
    """Step 3: ``std`` of every free column (offsets too; inf where the interval is unbounded),
    ``std_classic`` of the parameters, the correlation, the summary of the method, the 95 %
    quantiles, the condition numbers (``cond``: of the paper's parameters alone, eq. 25) and the
    warnings of the covariance."""

    std: dict[str, float]
    std_classic: dict[str, float]
    correlation: ParameterCorrelation
    summary: UncertaintySummary
    quantiles: dict[str, float]
    cond: float
    cond_unscaled: float
    cond_with_offsets: float
    warnings: tuple[str, ...]
    cov: np.ndarray | None = None  # of the free columns (the check's order)


def fit_uncertainty(check: ExcitationCheck, fitted: Estimate, settings: IdentificationSettings,
                    workers: int = 1) -> FitUncertainty:
    """Step 3: the covariance by ``settings.uncertainty.method`` (``workers`` threads) and what follows from it."""
    est, free, unbounded = fitted.estimator, list(check.free), check.unbounded
    u = settings.uncertainty
    unc = parameter_uncertainty(u.method, est, check.data, bandwidth=u.bandwidth, bandwidth_factor=u.bandwidth_factor,
                                min_bandwidth=u.min_bandwidth, replicates=u.bootstrap_replicates, seed=u.seed,
                                names=free, reported=(*PARAMETER_NAMES, *EXTRA_NAMES), workers=workers)
    sd_all, bad_variances = std_from_covariance(unc.cov, free)
    # cond(Theta_1,w^T Theta_1,w) of the paper's parameters alone (eq. 25); the nuisance offset
    # columns are reported separately
    param_cols = [i for i, n in enumerate(free) if n in PARAMETER_NAMES]
    if len(param_cols) < len(free):
        cond, cond_unscaled = scaled_condition(check.data.A[:, param_cols])
        cond_with_offsets = float(est.condition_number_)
    else:
        cond = float(est.condition_number_)
        cond_unscaled = float(getattr(est, "condition_number_unscaled_", float("nan")))
        cond_with_offsets = float("nan")
    std = {n: (math.inf if n in unbounded else v) for n, v in zip(free, sd_all.tolist())}
    std_classic = {n: (math.inf if n in unbounded else float(v)) for n, v in zip(free, est.std_)
                   if n in PARAMETER_NAMES}
    for n in unbounded - set(free):  # held parameters
        std[n] = math.inf
        if n in PARAMETER_NAMES:
            std_classic[n] = math.inf
    correlation = _correlation(unc.cov, free, unbounded)
    dof = None if unc.dof is None else {n: (float(v) if math.isfinite(v) else None)
                                        for n, v in zip(free, unc.dof) if n in PARAMETER_NAMES}
    return FitUncertainty(
        std, std_classic, ParameterCorrelation(tuple(correlation["names"]), tuple(map(tuple, correlation["matrix"]))),
        UncertaintySummary.of(unc.method.value, unc.details, dof),
        {n: float(q) for n, q in zip(free, unc.quantile()) if n in PARAMETER_NAMES or n in EXTRA_NAMES},
        cond, cond_unscaled, cond_with_offsets, tuple(unc.warnings) + tuple(bad_variances), unc.cov)


def _parameter_std(unc: FitUncertainty) -> dict[str, float]:
    return {n: v for n, v in unc.std.items() if n in PARAMETER_NAMES}


def check_plausibility(check: ExcitationCheck, fitted: Estimate, unc: FitUncertainty,
                       settings: IdentificationSettings, geometry: Geometry | None = None) -> tuple[str, ...]:
    """Step 4: :class:`ImplausibleError` for physically impossible values (``settings.fit.plausibility``),
    :class:`UnidentifiableError` for std above ``max_relative_std`` of the value (unless
    ``unexcited="report"``); the warnings of both. A model's breakaway levels are checked alike; its
    centre-of-mass offset against the size of the platform (``geometry``; :func:`.model_fit.noisy_extensions`)."""
    warnings: list[str] = []
    estimated = [(n, float(v)) for n, v in zip(check.free, fitted.coef)
                 if n in PARAMETER_NAMES and n not in check.unbounded]
    if settings.fit.plausibility:  # the breakaway levels of a model that has them are frictions too
        breakaway = [(n, float(v)) for n, v in zip(check.free, fitted.coef)
                     if n in BREAKAWAY_NAMES and n not in check.unbounded]
        refused, implausible = implausible_parameters(dict(estimated + breakaway), unc.std)
        if refused:
            raise ImplausibleError(refused, None, "")
        warnings += implausible
    limit = settings.fit.max_relative_std
    noisy = [Dependency(n, (), math.nan, relative_std=float(unc.std[n] / abs(v)))
             for n, v in estimated if unc.std[n] > limit * abs(v)]
    noisy += noisy_extensions(check, fitted.coef, unc.std, limit, geometry)
    if noisy and not settings.fit.reports_unexcited:
        centre = (", or the platform's size for a centre-of-mass offset" if any(d.name in CENTRE_NAMES for d in noisy)
                  else "")
        raise UnidentifiableError(noisy, f"weakly excited data (standard deviation above {100 * limit:g} % of the "
                                         f"value{centre}): ")
    return tuple(warnings + [f"weakly excited: {d.describe()}" for d in noisy])


def assemble(check: ExcitationCheck, fitted: Estimate, unc: FitUncertainty, warnings: Sequence[str], *,
             fixed: Mapping[str, float], settings: IdentificationSettings, geometry: Geometry,
             account: RowAccount, model: ModelSpec = PAPER_MODEL) -> Identification:
    """Step 5: the :class:`Identification` of the steps' results and the rows' account."""
    est, data = fitted.estimator, check.data
    theta = data.theta(est.coef_)
    offsets = theta[N_P:N_P + len(OFFSET_NAMES)] if settings.fit.torque_offsets else None
    parameters = Parameters.from_vector(theta[:N_P])
    residual_rms = data.residual_rms(est.coef_)
    extra, extra_std = extension_estimates(model, columns(fixed, settings.fit.torque_offsets, model)[0], theta,
                                           check.free, unc.cov, unc.std)
    for name in unsupported_breakaway(model, account.counts.stribeck_support):  # at the paper's law, unbounded
        extra[name] = getattr(parameters, FRICTION_GROUPS[name[-1]][1])
    return Identification(
        parameters=parameters, std=_parameter_std(unc),
        fixed=tuple(n for n in PARAMETER_NAMES if n in fixed),
        condition_number=unc.cond, condition_number_unscaled=unc.cond_unscaled,
        condition_number_with_offsets=unc.cond_with_offsets, residual_rms=residual_rms,
        n_rows=int(data.n_rows), n_samples=int(account.n_samples), blocks=tuple(account.blocks), settings=settings,
        geometry=geometry, sources=tuple(account.sources), notes=tuple(account.notes),
        estimator=getattr(est, "name", "") or type(est).__name__, std_classic=unc.std_classic,
        correlation=unc.correlation, uncertainty=unc.summary, quantiles=unc.quantiles,
        active_bounds=tuple(getattr(est, "active_", ())),
        downweighted_rows=int(np.count_nonzero(getattr(est, "downweighted_", []))),
        offsets={} if offsets is None else dict(zip(OFFSET_NAMES, offsets.tolist())),
        offsets_std={n: unc.std[n] for n in OFFSET_NAMES if n in unc.std},
        rows=account.counts, slip_events=tuple(account.slip_events),
        slip_thresholds=dict(account.slip_thresholds),
        warnings=tuple(check.warnings) + fitted.warnings + unc.warnings + tuple(warnings)
        + tuple(breakaway_warnings(extra, extra_std, parameters)),
        model=model, extra=extra, extra_std=extra_std, residual_ss=residual_sums(data, est.coef_))


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


