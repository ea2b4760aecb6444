"""The searches of the model's nonlinear values (issue 30, :mod:`agvdyn.model_spec`): the torque
delay and the Stribeck velocities, each a 1-D profile of the regression's concentrated likelihood

    J(x) = sum_g n_g log(RSS_g(x) / n_g)          (g: generalized coordinate)

(-2 log L of the regression with one residual variance per coordinate, those variances and the
linear parameters profiled out: one fit per evaluation of ``x``, values and residuals only,
:func:`search_fit`). The delay's J sums the chassis coordinates only by default (:func:`delay_evidence`:
the steering rows of our plant carry its steering joints' stick-slip, which looks like a torque lead).

Minimum: a coarse grid (the delay: the logs' sample period; a Stribeck velocity: factors of 2 on a
log scale), then a bounded Brent search (:func:`scipy.optimize.minimize_scalar`) between the grid
neighbours of the best point: sub-sample. Several Stribeck velocities (and the delay) are searched
coordinate-wise, one at a time with the others at their current value, in two sweeps (the second
only around the first's result).

Interval. For independent rows ``{x : J(x) <= J_min + 1}`` is the 68 % profile-likelihood interval
(chi^2_1). The rows are filtered and oversampled: their residuals are correlated over ``tau`` steps,
the integrated correlation time of the regression's scores that the HAC / jackknife bandwidth is
made of (:func:`.correlation.correlation_time`, reported as the uncertainty's
``correlation_time_steps``). The rows then carry about ``N / tau`` independent observations and J
overstates the information by ``tau``: the interval is ``{J <= J_min + tau}``, for a parabola
``J = (x - x0)^2 / s^2`` the std ``s sqrt(tau)``. Its ends are where the profile crosses that level,
found on the evaluated points by linear interpolation of ``sqrt(J - J_min)`` (exact for a parabola)
and refined by one more evaluation each; a side where the profile does not rise by ``tau`` within
the range is unbounded: std ``inf``. An optimum on a bound of its range is a warning and std ``inf``.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agvdyn.identification.model_fit import held_reason, unsupported_breakaway
from agvdyn.identification.plausibility import ImplausibleError
from agvdyn.identification.profile import Profile, profile_interval, profile_minimum, profile_std
from agvdyn.identification.regression import UnidentifiableError
from agvdyn.identification.search_uncertainty import SearchSpread, searched_spread, with_spread
from agvdyn.identification.settings import CHASSIS_COORDINATES, IdentificationSettings
from agvdyn.io import LogFile
from agvdyn.model_spec import BREAKAWAY_NAMES, STRIBECK_NAMES, ModelSpec

__all__ = ["concentrated_likelihood", "delay_evidence", "SearchResult", "search_model", "searched_values",
           "check_search_ranges", "search_settings", "searched_intervals", "identify_model", "model_identification",
           "ModelFit", "search_fit", "correlation_steps", "with_searched", "DELAY", "DELAY_GROUPS", "SEARCH_SWEEPS"]

#: The name of the delay's profile (``model.delay_s``); the Stribeck velocities are STRIBECK_NAMES.
DELAY = "delay_s"
#: The coordinate groups a delay's profile uses (:func:`delay_evidence`).
DELAY_GROUPS = ("chassis", "all")
#: Coordinate-wise sweeps over the searched values.
SEARCH_SWEEPS = 2
#: Grid step of a Stribeck velocity's search, a factor (log scale), and Brent's tolerance (a factor).
STRIBECK_GRID_FACTOR = 2.0
STRIBECK_XATOL = math.log(1.05)
#: Brent's tolerance of the delay, in sample periods.
DELAY_XATOL_SAMPLES = 0.02


def concentrated_likelihood(residual_ss: Mapping[str, tuple[float, int]],
                            reference_rows: Mapping[str, int] | None = None) -> float:
    """``J = sum_g n_g log(RSS_g / n_g)`` of the residual sum of squares and rows of each coordinate
    group ``g`` (-2 log L of the regression up to a constant, the variances profiled out). With
    ``reference_rows``, ``n_g`` of those groups is replaced by theirs in front of the log (the mean
    square of the group's rows times the reference count): fits on a few rows more or less (a delay
    drops the rows whose shifted torque leaves the stretch) compare without a jump."""
    total = 0.0
    for group, (rss, n) in residual_ss.items():
        if not (n > 0 and math.isfinite(rss) and rss >= 0):
            raise ValueError(f"residual_ss[{group!r}] = ({rss!r}, {n!r}): expected a finite sum of squares >= 0 "
                             "and a number of rows > 0")
        weight = n if reference_rows is None else reference_rows.get(group, n)
        total += weight * math.log(max(rss, np.finfo(float).tiny) / n)
    return total


@dataclass(frozen=True)
class SearchResult:
    """The searched values of a model: ``model`` resolved (delay a number, Stribeck velocities given),
    the last ``profiles`` of each searched value (:data:`DELAY`, STRIBECK_NAMES), the evaluations made."""

    model: ModelSpec
    profiles: dict[str, Profile] = field(default_factory=dict)
    fits: int = 0


def _resolved(model: ModelSpec, values: Mapping[str, float]) -> ModelSpec:
    changes = {}
    if DELAY in values:
        changes["delay"] = values[DELAY]
    if any(n in values for n in STRIBECK_NAMES):
        changes["stribeck_velocities"] = tuple(values[n] for n in STRIBECK_NAMES)
    return model.replace(**changes)


def search_model(objective: Callable[[ModelSpec, str], float], model: ModelSpec, *, sample_time: float,
                 sweeps: int = SEARCH_SWEEPS, start: Mapping[str, float] | None = None) -> SearchResult:
    """Resolve ``model``'s searches (see the module docstring): the delay (``"auto"``) over
    ``delay_range`` on a grid of ``sample_time``, the Stribeck velocities (``stribeck`` without
    ``stribeck_velocities``) over ``stribeck_range`` on a log grid; coordinate-wise in ``sweeps``
    sweeps when there are several. ``objective(spec, name)``: J of a resolved spec
    (:func:`concentrated_likelihood` of its fit) on the rows that are evidence for the value ``name``
    being searched. ``start``: values found before (e.g. each extension's alone) for all searched
    ones: one sweep of bracket searches around them, no grid. Checking the ranges against the logs is
    the caller's (:func:`check_search_ranges`)."""
    values: dict[str, float] = {}
    searched: list[str] = []
    if model.delay == "auto":
        lo, hi = model.delay_range
        values[DELAY] = min(max(0.0, lo), hi)
        searched.append(DELAY)
    if model.stribeck and model.stribeck_velocities is None:
        lo, hi = model.stribeck_range
        values.update({n: math.sqrt(lo * hi) for n in STRIBECK_NAMES})  # a held group's stays there
        searched += list(model.free_stribeck_names)
    started = start is not None and all(n in start for n in searched)
    if started:
        values.update({n: float(start[n]) for n in searched})
    profiles: dict[str, Profile] = {}
    fits = 0
    for sweep in range(1 if started or len(searched) < 2 else sweeps):
        for name in searched:
            def one(x: float, name: str = name) -> float:
                return objective(_resolved(model, {**values, name: x}), name)

            if name == DELAY:
                found = profile_minimum(one, model.delay_range, step=sample_time, name=name,
                                        xatol=DELAY_XATOL_SAMPLES * sample_time,
                                        start=values[name] if sweep or started else None)
            else:
                found = profile_minimum(one, model.stribeck_range, step=math.log(STRIBECK_GRID_FACTOR), name=name,
                                        xatol=STRIBECK_XATOL, log_scale=True,
                                        start=values[name] if sweep or started else None)
            profiles[name], values[name] = found, found.best
            fits += found.fits
    return SearchResult(_resolved(model, values), profiles, fits)


def _sample_time(item: Any) -> float:
    return float((item.first() if isinstance(item, LogFile) else item).sample_time)


def check_search_ranges(model: ModelSpec, sample_time: float, settings: IdentificationSettings) -> None:
    """A delay search's range against the logs: at least one sample period wide (a delay within one
    sample is the ``torque_lead``'s), within the rows a stretch drops at each end (the filter's
    edge guard: further out, the shifted torques of the kept rows would leave the stretch)."""
    if model.delay != "auto":
        return
    lo, hi = model.delay_range
    if hi - lo < sample_time:
        raise ValueError(f"model: delay_range=({lo:g}, {hi:g}) s is narrower than one sample period of the logs "
                         f"({sample_time:g} s): expected a range of at least one sample period (a lag within one "
                         "sample is the torque lead's: --torque-lead)")
    limit = settings.rows.seconds(settings.rows.edge_guard)
    if max(abs(lo), abs(hi)) > limit:
        raise ValueError(f"model: delay_range=({lo:g}, {hi:g}) s reaches beyond {limit:g} s, the rows each stretch "
                         f"drops at its ends (edge_guard {settings.rows.edge_guard:g} / cutoff "
                         f"{settings.rows.filter.cutoff:g} rad/s): expected |delay| <= {limit:g} s")


def delay_evidence(residual_ss: Mapping[str, tuple[float, int]], groups: str = "chassis"
                   ) -> Mapping[str, tuple[float, int]]:
    """The coordinate groups whose residuals are the delay's evidence: ``"all"``, or ``"chassis"``
    (x_ch, y_ch, gamma_ch; all when the fit has none). The steering rows of a passively steered
    vehicle also carry the steering joints' stick-slip, which the tanh law lacks and which looks like
    a torque lead: measured on our plant's effect-free identification log (seed 1), they put the
    delay at -7 ms (left) and beyond -12 ms (right), the chassis rows at -1 to 0 ms; with the
    model's tanh friction in the plant (``PlantSettings(coulomb="tanh")``) all agree within 1 ms,
    as they do on the MuJoCo plant."""
    if groups not in DELAY_GROUPS:
        raise ValueError(f"delay_groups={groups!r}: expected one of {list(DELAY_GROUPS)}")
    chassis = {g: v for g, v in residual_ss.items() if g in CHASSIS_COORDINATES}
    return chassis if groups == "chassis" and chassis else residual_ss


def search_settings(settings: IdentificationSettings) -> IdentificationSettings:
    """The settings of the search's fits: values and residuals only (classic uncertainty, no
    refusal: a Stribeck velocity far off may leave a level unexcited without stopping the search)."""
    return settings.replace(uncertainty="classic", plausibility=False, unexcited="report", max_relative_std=math.inf)


def searched_values(model: ModelSpec) -> dict[str, float]:
    """The delay and the Stribeck velocities a (resolved) model has, by name (none while ``auto``)."""
    out = {} if model.delay == "auto" else {DELAY: float(model.delay)}
    if model.stribeck_velocities is not None:
        out.update(zip(STRIBECK_NAMES, model.stribeck_velocities))
    return out


def searched_intervals(found: SearchResult, objective: Callable[[ModelSpec, str], float], correlation_steps: float
                       ) -> tuple[dict[str, float], tuple[str, ...], int, dict[str, tuple[float, float]]]:
    """The std of each searched value (see the module docstring; ``inf`` on a bound or where the
    profile does not rise by ``correlation_steps``), the warnings, the evaluations added, and each
    value's interval (an end ``-inf`` / ``inf`` where the profile does not rise enough)."""
    stds, warnings, fits, intervals = {}, [], 0, {}
    values = searched_values(found.model)
    for name, profile in found.profiles.items():
        def one(x: float, name: str = name) -> float:
            return objective(_resolved(found.model, {**values, name: x}), name)

        interval, grown = profile_interval(profile, correlation_steps, one)
        fits += grown.fits - profile.fits
        intervals[name] = interval
        unit = "s" if name == DELAY else "rad/s"
        bound = grown.on_bound()
        stds[name] = math.inf if bound is not None else profile_std(interval)
        lo, hi = profile.bounds
        if bound is not None:
            side = "lower" if bound == lo else "upper"
            warnings.append(f"model: {name} = {values[name]:.4g} {unit} sits on the {side} bound of its search range "
                            f"({lo:g}, {hi:g}) {unit}: the data put it there or beyond; its std is unbounded "
                            f"(widen --{'delay' if name == DELAY else 'stribeck'}-range, or the model does without it)")
        elif not math.isfinite(stds[name]):
            warnings.append(f"model: {name} = {values[name]:.4g} {unit}: the profile of the residual does not rise "
                            f"enough within ({lo:g}, {hi:g}) {unit} on both sides: the data do not determine it "
                            "(std unbounded)")
    return stds, tuple(warnings), fits, intervals


def correlation_steps(ident: Any, refit: Callable[[], Any]) -> float:
    """The residuals' correlation time (steps) of a fit: its uncertainty's ``correlation_time_steps``
    (HAC, jackknife, bootstrap), else that of ``refit()`` (a fit with the HAC; classic has none)."""
    found = getattr(ident.uncertainty, "correlation_time_steps", None)
    if found is None:
        found = refit().uncertainty.correlation_time_steps
    return max(1.0, float(found))


def identify_model(logs: Any, platform: Any = None, *, model: ModelSpec, fixed: Mapping[str, float] | None = None,
                   settings: IdentificationSettings = IdentificationSettings(), estimator: Any = None,
                   experiment: str = "auto", keep_blocks: bool = True, workers: int | None = None,
                   delay_groups: str = "chassis") -> Any:
    """:func:`.pipeline.identify` of ``model`` with its searches resolved (see the module docstring):
    the delay ``"auto"`` and unknown Stribeck velocities found on the profile of the residual (the
    search's fits values only: classic uncertainty, no refusal), then the final fit at the optimum
    with ``settings``. The result's ``model`` is the resolved spec; the searched values' std (the
    profile interval corrected for the residuals' correlation) are ``extra_std`` (Stribeck velocities)
    and ``delay_std_s``; an optimum on a bound or an undetermined value has std ``inf`` and a warning.
    ``delay_groups``: the rows of the delay's profile (:func:`delay_evidence`). The other keywords are
    :func:`.pipeline.identify`'s. Raises ValueError for a delay range narrower
    than one sample period or beyond the stretches' edges (:func:`check_search_ranges`)."""
    return model_identification(logs, platform, model=model, fixed=fixed, settings=settings, estimator=estimator,
                                experiment=experiment, keep_blocks=keep_blocks, workers=workers,
                                delay_groups=delay_groups).identification


@dataclass(frozen=True, eq=False)
class ModelFit:
    """:func:`model_identification`'s result: the ``identification``, the ``fits`` made, the searched
    values' ``stds`` and the search's ``warnings`` (both already in the identification)."""

    identification: Any
    fits: int
    stds: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    spread: SearchSpread = field(default_factory=SearchSpread)
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)


def model_identification(logs: Any, platform: Any = None, *, model: ModelSpec, fixed: Mapping[str, float] | None = None,
                         settings: IdentificationSettings = IdentificationSettings(), estimator: Any = None,
                         experiment: str = "auto", keep_blocks: bool = True, workers: int | None = None,
                         delay_groups: str = "chassis", start: Mapping[str, float] | None = None) -> ModelFit:
    """:func:`identify_model` with what it made (:class:`ModelFit`); ``start``: see :func:`search_model`.

    A breakaway level the fit refuses (too uncertain, its searched Stribeck velocity's uncertainty
    included, or impossible), or whose searched Stribeck velocity has an unbounded interval
    (:func:`unbounded_levels`; with ``unexcited="report"`` that level is reported with std inf instead),
    is held at the paper's law (``ModelSpec.held``) and the model fitted again, the reason a warning:
    the data do not show that group's breakaway, the other parameters still stand. A refusal of any
    other parameter is raised."""
    reasons: dict[str, str] = {}
    while True:
        try:
            fit = _model_identification(logs, platform, model=model, fixed=fixed, settings=settings,
                                        estimator=estimator, experiment=experiment, keep_blocks=keep_blocks,
                                        workers=workers, delay_groups=delay_groups, start=start)
        except (UnidentifiableError, ImplausibleError) as exc:
            refused = refused_levels(exc, model)
            if not refused:
                raise
            model = model.replace(held=model.held + tuple(refused))
            reasons.update(refused)
            continue
        loose = unbounded_levels(fit, model)
        if loose and not settings.fit.reports_unexcited:  # a level at a w_s the data do not fix: held too
            model = model.replace(held=model.held + tuple(loose))
            reasons.update(loose)
            continue
        fit = with_unbounded(fit, loose)  # reported: its interval unbounded
        if not reasons:
            return fit
        said = tuple(_undetermined(n, why, held=True) for n, why in reasons.items())
        generic = {held_reason(n) for n in reasons}  # said with the refusal's reason instead
        warnings = said + tuple(w for w in fit.identification.warnings if w not in generic)
        return dataclasses.replace(fit, identification=dataclasses.replace(fit.identification, warnings=warnings),
                                   warnings=said + fit.warnings)


def unbounded_levels(fit: ModelFit, model: ModelSpec) -> dict[str, str]:
    """The breakaway levels (not yet held) whose searched Stribeck velocity has an unbounded interval (on a
    bound of its range, or a profile that does not rise), with why: the level is fitted at that velocity
    only, and moves without limit beyond the range (its std would not say so)."""
    ident = fit.identification
    values = dict(zip(STRIBECK_NAMES, ident.model.stribeck_velocities or ()))
    unsupported = unsupported_breakaway(ident.model, ident.rows.stribeck_support)  # held already, said why
    return {f"d_s{w[-1]}": (f"its Stribeck velocity {w} = {values.get(w, math.nan):.3g} rad/s is not determined "
                            f"(std unbounded: on a bound of the search range {model.stribeck_range}, or the profile "
                            "does not rise), so neither is the level")
            for w in model.free_stribeck_names
            if not math.isfinite(fit.stds.get(w, 0.0)) and f"d_s{w[-1]}" not in unsupported}


def with_unbounded(fit: ModelFit, levels: Mapping[str, str]) -> ModelFit:
    """``fit`` with the breakaway ``levels`` (name: why) reported undetermined: std inf and a warning each."""
    if not levels:
        return fit
    ident = fit.identification
    said = tuple(_undetermined(n, why, held=False) for n, why in levels.items())
    ident = dataclasses.replace(ident, extra_std={**ident.extra_std, **dict.fromkeys(levels, math.inf)},
                                warnings=said + ident.warnings)
    return dataclasses.replace(fit, identification=ident, warnings=said + fit.warnings)


def _undetermined(name: str, why: str, held: bool) -> str:
    """The warning of a breakaway level the data do not determine (``held``: at the paper's law)."""
    where = ", held at the paper's law d_s = d_c" if held else ""
    return f"{name} not determined by these data{where} (interval unbounded): {why}"


def refused_levels(exc: Exception, model: ModelSpec) -> dict[str, str]:
    """The breakaway levels (not yet held by ``model``) a refusal names, with its description of each."""
    named = getattr(exc, "dependencies", ()) or getattr(exc, "implausible", ())
    return {d.name: " ".join(d.describe().split()) for d in named
            if d.name in BREAKAWAY_NAMES and d.name not in model.held}


def _model_identification(logs: Any, platform: Any, *, model: ModelSpec, fixed: Mapping[str, float] | None,
                          settings: IdentificationSettings, estimator: Any, experiment: str, keep_blocks: bool,
                          workers: int | None, delay_groups: str, start: Mapping[str, float] | None) -> ModelFit:
    """One :func:`model_identification` of ``model`` as it is (its held levels held)."""
    from agvdyn.identification.lifted import experiment_of
    from agvdyn.identification.pipeline import identify, platform_for
    from agvdyn.identification.settings import DEFAULT_FIXED
    from agvdyn.io import Log

    if not isinstance(model, ModelSpec):
        raise ValueError(f"model={model!r}: expected an agvdyn.model_spec.ModelSpec")
    items = [logs] if isinstance(logs, (Log, LogFile)) else list(logs)
    options = dict(fixed=DEFAULT_FIXED if fixed is None else fixed, estimator=estimator, experiment=experiment,
                   workers=workers)
    if model.resolved:
        return ModelFit(identify(items, platform, settings=settings, keep_blocks=keep_blocks, model=model, **options), 1)
    items = [x.load() if isinstance(x, LogFile) and not x.long else x for x in items]  # read once, fitted often
    if experiment_of(items, experiment) != "vehicle":
        raise ValueError("lifted-wheel logs: their model is the paper's (identify_lifted); a model search needs "
                         "vehicle logs")
    geometry = platform_for(items, platform)
    sample_time = max(_sample_time(x) for x in items)
    check_search_ranges(model, sample_time, settings)
    reference: dict[str, int] = {}

    def objective(spec: ModelSpec, name: str) -> float:
        fit = search_fit(items, geometry, spec, settings, **options)
        if not reference:  # the rows of the first fit: every J scaled to them (see concentrated_likelihood)
            reference.update((g, n) for g, (_, n) in fit.residual_ss.items())
        groups = delay_evidence(fit.residual_ss, delay_groups) if name == DELAY else fit.residual_ss
        return concentrated_likelihood(groups, reference)

    found = search_model(objective, model, sample_time=sample_time, start=start)
    final = identify(items, geometry, settings=settings, keep_blocks=keep_blocks, model=found.model, **options)
    hac = functools.partial(search_fit, items, geometry, found.model, settings, uncertainty="hac", **options)
    steps = correlation_steps(final, hac)
    stds, warnings, fits, intervals = searched_intervals(found, objective, steps)
    stds.update({w: math.inf for w in STRIBECK_NAMES if model.stribeck and w not in model.free_stribeck_names})
    values = searched_values(found.model)
    spread = searched_spread(final, values, intervals, {n: p.bounds for n, p in found.profiles.items()},
                             lambda at: search_fit(items, geometry, _resolved(found.model, at), settings, **options))
    made = found.fits + fits + spread.fits + 1 + (final.uncertainty.correlation_time_steps is None)
    return ModelFit(with_searched(final, stds, warnings, spread), made, stds, warnings, spread, intervals)


def search_fit(items: Sequence[Any], geometry: Any, model: ModelSpec, settings: IdentificationSettings, *,
               fixed: Mapping[str, float], estimator: Any, experiment: str, workers: int | None,
               uncertainty: str = "classic") -> Any:
    """One fit of a search: values and residuals (:func:`search_settings`, with ``uncertainty``), without
    what only the final fit needs (the change test within a recording, the sign diagnosis): the row
    pass of each log in memory (:func:`.pipeline.row_passes`) and one regression (:func:`.fit.fit_blocks`);
    files read in pieces go through :func:`.pipeline.identify`."""
    from agvdyn.identification.fit import fit_blocks
    from agvdyn.identification.pipeline import identify, row_passes

    quick = search_settings(settings).replace(uncertainty=uncertainty)
    if any(isinstance(x, LogFile) for x in items):
        return identify(items, geometry, fixed=fixed, settings=quick, estimator=estimator, experiment=experiment,
                        keep_blocks=False, workers=workers, model=model)
    blocks = [b for rows in row_passes(items, geometry, quick, model=model) for b in rows.blocks]
    return fit_blocks(blocks, geometry, fixed=fixed, settings=quick, estimator=estimator, model=model)


def with_searched(ident: Any, stds: Mapping[str, float], warnings: Sequence[str],
                  spread: SearchSpread = SearchSpread()) -> Any:
    """The identification with the searched values' std (Stribeck velocities in ``extra_std``, the
    delay's ``delay_std_s``), the search's warnings and the estimates' ``spread`` over the searched
    values' intervals in their std (:func:`.search_uncertainty.with_spread`: may refuse)."""
    extra_std = {**ident.extra_std, **{n: s for n, s in stds.items() if n in STRIBECK_NAMES}}
    changes: dict[str, Any] = {"extra_std": extra_std, "warnings": ident.warnings + tuple(warnings)}
    if DELAY in stds:
        changes["delay_std_s"] = stds[DELAY]
    return with_spread(dataclasses.replace(ident, **changes), spread)
