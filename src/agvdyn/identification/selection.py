"""Selection of the model by the data (issue 30): the paper's model, each extension alone and all
together are fitted (:func:`.model_search.identify_model`) and scored; ``auto`` keeps an extension
only when it lowers both the BIC and the held-out error.

Scores of a candidate:

* ``residual_rms``: RMS of the residuals over all rows of the fit.
* ``bic``: the Bayesian information criterion on the *effective* sample. The rows are filtered and
  oversampled, their residuals correlated over ``tau`` steps (the integrated correlation time of
  the paper model's scores, the uncertainty's ``correlation_time_steps``): N rows carry about
  ``N_eff = N / tau`` independent observations, and the concentrated likelihood
  ``J = sum_g n_g log(RSS_g / n_g)`` overstates the evidence by the same factor. So
  ``BIC = J / tau + k log(N_eff)`` (k: estimated parameters, searched values included). With the
  raw count (``J + k log N``) a spurious parameter, whose ``Delta J`` is ``tau chi^2_1``, would
  pass whenever ``chi^2_1 > log(N) / tau`` -- most of the time for ``tau`` of tens of steps.
  Every candidate is scored with the paper model's ``tau`` and row counts per coordinate (``J``
  of a candidate uses its mean square per coordinate times the paper's rows), so that a few rows
  more or less (a delay's interpolation at a stretch's end) do not count as evidence.
* ``nrmse_holdout``: blocked cross-validation, leave-one-part-out. Each segment's rows (per log and
  label) are cut in ``parts`` contiguous parts in time; fold j refits without part j of every
  segment (nor the rows within ``2 tau`` steps of it, at most half the part: correlated residuals leak,
  a longer gap drops segments; :data:`.selection_rows.GAP_PART_FRACTION`) and predicts part j. Leaving out
  a whole segment label is impossible on the paper's sequence: each excites its parameters (Table 1). The NRMSE
  ``RMS(measured - model) / RMS(measured)`` (:func:`agvdyn.validation.nrmse`) is pooled per
  ``segment:coordinate`` over the folds, on the kept rows, and averaged over the keys. The searched
  values (delay, Stribeck velocities) stay at the whole data's optimum in the folds.
* ``nrmse_validation``: the caller's score on logs not used for the fit (``validation``, e.g. the
  CLI's ``--validation`` through :func:`agvdyn.validation.validate`); None without. Shown, not voting:
  one validation log ranks two models by all their errors, not by the effect (measured on our plant, a
  real 6 ms delay: the delay model predicts the lane change as well as the effect-free fit does, yet worse
  than the lagged paper fit on 4 of 10 seeds, whose bias happened to offset the plant's other errors there;
  docs/identification.md).

Like with like (:mod:`.selection_rows`): two models are compared on the rows where their difference is
evidence. The scores above sum all coordinates (the table's figures); where two models differ by the
delay alone, both are scored on the delay's evidence rows, those its search uses (the chassis rows,
:func:`.model_search.delay_evidence`): the steering rows carry the steering joints' stick-slip, which the
tanh law lacks and which looks like a torque lead, and would vote any real delay down on our plant.
The Stribeck law likewise on the rows of the joint groups whose breakaway level the fit determined
(the wheels': chassis rows; none determined: never kept); ``k`` there counts the columns with an entry on
those rows (:func:`.selection_rows.rows_parameter_count`).

``auto`` (:func:`chosen_model`): an extension passes when it lowers both the BIC and the held-out
error of the paper's model on their comparison rows and none of its parameters is undetermined (std
``inf``, or above ``max_relative_std`` of the value for the breakaway levels and the paper's parameters)
or implausible; several passing ones are combined and the combination is kept only when it lowers both
again against the best single one (the largest BIC gain over the paper's), on their comparison rows.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.fit import fit_blocks
from agvdyn.identification.model_fit import held_parameters, linear_values, rejected_extension
from agvdyn.identification.model_search import (
    DELAY,
    ModelFit,
    concentrated_likelihood,
    correlation_steps,
    model_identification,
    search_fit,
    search_settings,
    searched_values,
    with_searched,
)
from agvdyn.identification.plausibility import ImplausibleError
from agvdyn.identification.regression import UnidentifiableError
from agvdyn.identification.selection_rows import (HOLDOUT_PARTS, ROWS_CHOICES, bic_on_rows, bic_parameter_count,
                                                  column_groups, comparison_rows, determined_breakaway,
                                                  holdout_nrmse, holdout_of_sums, holdout_parts,
                                                  rows_disagree, rows_parameter_count)
from agvdyn.identification.settings import DEFAULT_FIXED, IdentificationSettings
from agvdyn.io import Log, LogFile
from agvdyn.model_spec import BREAKAWAY_NAMES, CENTRE_NAMES, DELAY_RANGE, STRIBECK_NAMES, STRIBECK_RANGE, ModelSpec

__all__ = ["ModelScore", "ModelSelection", "compare_models", "candidate_models", "added_parameters", "holdout_nrmse",
           "holdout_parts", "information_bic", "chosen_model", "versus", "HOLDOUT_PARTS"]

#: A refit on blocks: returns the predictor of a block's model torques (n, n_k).
Refit = Callable[[Sequence[EquationBlock]], Callable[[EquationBlock], np.ndarray]]


def candidate_models(*, delay_range: tuple[float, float] = DELAY_RANGE,
                     stribeck_range: tuple[float, float] = STRIBECK_RANGE) -> tuple[ModelSpec, ...]:
    """The models compared: the paper's, each extension alone (``stribeck`` and ``delay`` searched),
    all three together."""
    base = ModelSpec(delay_range=delay_range, stribeck_range=stribeck_range)
    return (base, base.replace(friction="stribeck"), base.replace(delay="auto"), base.replace(com_offset=True),
            base.replace(friction="stribeck", delay="auto", com_offset=True))


def added_parameters(model: ModelSpec) -> tuple[str, ...]:
    """The parameters a model adds to the paper's (searched values included): ``d_s*, w_s*`` of
    ``stribeck`` (``w_s*`` only when searched), ``delay_s`` of a searched delay, ``x_c, y_c``."""
    out: tuple[str, ...] = ()
    if model.stribeck:
        out += BREAKAWAY_NAMES + (STRIBECK_NAMES if model.stribeck_velocities is None else ())
    if model.delay == "auto":
        out += ("delay_s",)
    return out + (CENTRE_NAMES if model.com_offset else ())


def information_bic(residual_ss: Mapping[str, tuple[float, int]], k: int, correlation_steps: float,
                    reference_rows: Mapping[str, int] | None = None) -> tuple[float, float, float]:
    """``(BIC, J, N_eff)`` of a fit: ``J`` (:func:`.model_search.concentrated_likelihood`, with the
    mean square of each group times ``reference_rows`` of it when given), ``N_eff = N / tau`` and
    ``BIC = J / tau + k log(N_eff)`` (see the module docstring)."""
    if not (correlation_steps >= 1 and math.isfinite(correlation_steps)):
        raise ValueError(f"correlation_steps={correlation_steps!r}: expected a finite number >= 1 (steps)")
    rows = {g: (reference_rows or {}).get(g, n) for g, (_, n) in residual_ss.items()}
    j = concentrated_likelihood(residual_ss, rows)
    n_eff = sum(rows.values()) / correlation_steps
    return j / correlation_steps + k * math.log(n_eff), j, n_eff


@dataclass(frozen=True, eq=False)
class ModelScore:
    """One candidate of :func:`compare_models`: the ``model`` asked (searches ``"auto"``), the
    ``fitted`` one (resolved), its scores (see the module docstring), ``k`` estimated parameters,
    ``undetermined``: added parameters whose std is infinite (never chosen), ``error``: why the fit
    was refused (None), ``fits``: identifications made (searches and folds included); per row class
    (:meth:`on_rows`): ``residual_ss`` per coordinate group, ``holdout_sums`` per ``segment:coordinate``,
    the ``correlation_steps`` and ``reference_rows`` of the BIC; ``versus_paper``: the comparison with
    the paper's model that ``auto`` made (rows, both models' BIC and held-out error on them)."""

    model: ModelSpec
    fitted: ModelSpec | None = None
    bic: float = math.nan
    likelihood: float = math.nan
    k: int = 0
    residual_rms: float = math.nan
    nrmse_holdout: float = math.nan
    nrmse_validation: float | None = None
    undetermined: tuple[str, ...] = ()
    error: str | None = None
    chosen: bool = False
    fits: int = 0
    identification: Any = field(default=None, repr=False)
    residual_ss: Mapping[str, tuple[float, int]] = field(default_factory=dict, repr=False)
    holdout_sums: Mapping[str, tuple[float, float]] = field(default_factory=dict, repr=False)
    correlation_steps: float = math.nan
    reference_rows: Mapping[str, int] = field(default_factory=dict, repr=False)
    columns: Mapping[str, tuple[str, ...]] = field(default_factory=dict, repr=False)
    versus_paper: dict[str, Any] | None = None

    @property
    def label(self) -> str:
        return self.model.label

    @property
    def parameters_added(self) -> tuple[str, ...]:
        return added_parameters(self.model)

    def on_rows(self, groups: Sequence[str] | None) -> tuple[float, float]:
        """``(BIC, held-out NRMSE)`` on the coordinate groups ``groups`` (:mod:`.selection_rows`); all rows
        (``bic``, ``nrmse_holdout``) when None or without the per row class sums; NaN on no rows (``()``)."""
        if groups is None or not self.residual_ss or not self.holdout_sums:
            return self.bic, self.nrmse_holdout
        if not groups:
            return math.nan, math.nan
        k = rows_parameter_count(self.k, self.model, self.columns, groups)
        return (bic_on_rows(self.residual_ss, k, self.correlation_steps, self.reference_rows, groups),
                holdout_of_sums(self.holdout_sums, groups))

    @property
    def usable(self) -> bool:
        """Fitted, every added parameter determined, scores finite."""
        return (self.error is None and not self.undetermined and math.isfinite(self.bic)
                and math.isfinite(self.nrmse_holdout))

    def to_dict(self) -> dict[str, Any]:
        """The JSON entry of ``model_selection``."""
        def clean(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else float(x)

        return {"model": self.label, "parameters_added": list(self.parameters_added), "bic": clean(self.bic),
                "nrmse_holdout": clean(self.nrmse_holdout), "nrmse_validation": clean(self.nrmse_validation),
                "residual_rms": clean(self.residual_rms), "chosen": self.chosen,
                "undetermined": list(self.undetermined), "error": self.error,
                "versus_paper": None if self.versus_paper is None else {
                    k: (clean(v) if isinstance(v, float) else v) for k, v in self.versus_paper.items()}}


def versus(a: ModelScore, b: ModelScore, rows: str = "evidence") -> dict[str, Any]:
    """The comparison of ``a`` with ``b``: the ``rows`` (coordinate groups, or ``"all"``;
    :func:`.selection_rows.comparison_rows` when ``rows`` is ``"evidence"``), both BICs and held-out
    errors on them, both validation scores (None without a validation log; shown, not voting: see the
    module docstring), and whether ``a`` lowers both the BIC and the held-out error (and is usable)."""
    if rows not in ROWS_CHOICES:
        raise ValueError(f"rows={rows!r}: expected one of {list(ROWS_CHOICES)}")
    friction = determined_breakaway((a if a.model.stribeck else b).identification)  # its evidence rows
    ss = b.residual_ss or a.residual_ss
    groups = comparison_rows(a.model, b.model, ss, friction) if rows == "evidence" else None
    (bic, holdout), (bic_b, holdout_b) = a.on_rows(groups), b.on_rows(groups)
    return {"rows": "all" if groups is None else list(groups), "bic": bic, "bic_other": bic_b,
            "nrmse_holdout": holdout, "nrmse_holdout_other": holdout_b,
            "nrmse_validation": a.nrmse_validation, "nrmse_validation_other": b.nrmse_validation,
            "better": a.usable and math.isfinite(bic) and bic < bic_b and holdout < holdout_b}


def _better(a: ModelScore, b: ModelScore, rows: str = "evidence") -> bool:
    """``a`` lowers both the BIC and the held-out error of ``b`` on their comparison rows (and is usable)."""
    return bool(versus(a, b, rows)["better"])


def chosen_model(scores: Sequence[ModelScore], combine: Callable[[ModelSpec], ModelScore] | None = None,
                 rows: str = "evidence") -> tuple[int, list[ModelScore]]:
    """``auto``'s choice among ``scores`` (the paper's model first, then single extensions): the
    extensions that lower both BIC and held-out error against the paper's model pass (on their
    comparison rows, :func:`versus`; ``rows="all"``: all rows, the rule before like with like); one
    passed: it; several: their combination (``combine`` fits it, or the score of that model among
    ``scores``), kept only when it lowers both against the best single one (the largest BIC gain over
    the paper's on its rows). Returns the index of the choice in the (possibly extended) list of scores."""
    scores = list(scores)
    paper = scores[0]
    singles = [s for s in scores[1:] if len(s.model.extensions) == 1]
    passed = [s for s in singles if _better(s, paper, rows)]
    if not passed:
        return 0, scores
    best = min(passed, key=lambda s: (lambda v: v["bic"] - v["bic_other"])(versus(s, paper, rows)))
    if len(passed) == 1:
        return scores.index(best), scores
    spec = passed[0].model
    for s in passed[1:]:
        spec = spec.replace(friction="stribeck" if (spec.stribeck or s.model.stribeck) else "paper",
                            delay="auto" if "delay" in spec.extensions + s.model.extensions else 0.0,
                            com_offset=spec.com_offset or s.model.com_offset)
    found = [s for s in scores if s.model == spec]
    if found:
        combo = found[0]
    else:
        if combine is None:
            return scores.index(best), scores
        combo = combine(spec)
        scores.append(combo)
    return (scores.index(combo) if _better(combo, best, rows) else scores.index(best)), scores


@dataclass(frozen=True, eq=False)
class ModelSelection:
    """Result of :func:`compare_models`: the ``scores`` (paper first), the ``chosen`` index, the
    identification of the chosen model, the correlation time ``tau`` (steps) and effective rows."""

    scores: tuple[ModelScore, ...]
    chosen: int
    correlation_steps: float
    n_effective: float
    parts: int = HOLDOUT_PARTS

    @property
    def identification(self) -> Any:
        return self.scores[self.chosen].identification

    @property
    def model(self) -> ModelSpec | None:
        return self.scores[self.chosen].fitted

    @property
    def fits(self) -> int:
        return sum(s.fits for s in self.scores)

    def to_list(self) -> list[dict[str, Any]]:
        """The JSON ``model_selection``: one entry per candidate."""
        return [s.to_dict() for s in self.scores]


def _refit(model: ModelSpec, geometry: Any, fixed: Mapping[str, float], settings: IdentificationSettings,
           estimator: Any, counts: Any = None) -> Refit:
    """The held-out refit of a fitted (resolved) model on blocks: values only (:func:`.model_search.search_settings`);
    ``counts``: the whole fit's row counts (its breakaway levels without support held in the folds as there)."""
    quick = search_settings(settings)
    account = {} if counts is None else {"counts": counts}

    def refit(blocks: Sequence[EquationBlock]) -> Callable[[EquationBlock], np.ndarray]:
        fit = fit_blocks(blocks, geometry, fixed=fixed, settings=quick, estimator=estimator, model=model, **account)
        p, offsets = fit.parameters.to_vector(), fit.offset_vector
        extra = linear_values(model, fit.extra, fit.parameters)
        return lambda b: b.model_torque(p, offsets, extra)

    return refit


def _undetermined(model: ModelSpec, ident: Any, limit: float) -> tuple[str, ...]:
    """What the data leave undetermined in a fit of ``model``: added parameters without a finite std
    (the delay's: ``delay_std_s``; not those held by design, :func:`held_parameters`, nor their w_s),
    breakaway levels and paper parameters whose std exceeds ``limit`` of their value (the extension's
    columns nearly collinear with theirs)."""
    def finite(x: float | None) -> bool:
        return x is not None and math.isfinite(x)

    held = held_parameters(model, ident)
    held += tuple(f"w_s{n[-1]}" for n in held if n in BREAKAWAY_NAMES)  # the velocity of a level at the paper's law
    stds = {**{n: v for n, v in ident.extra_std.items() if n not in held}, DELAY: ident.delay_std_s}
    out = [n for n in added_parameters(model) if n not in held and not finite(stds.get(n))]
    values = {**{n: getattr(ident.parameters, n) for n in ident.std}, **ident.extra}
    weak = [n for n, sd in {**ident.std, **{n: stds[n] for n in BREAKAWAY_NAMES if n in stds}}.items()
            if n not in out and (not finite(sd) or sd > limit * abs(values[n]))]
    return tuple(out + weak)


@dataclass(frozen=True, eq=False)
class _Scoring:
    """What every candidate is scored with: the logs and the fit's keywords, the paper model's
    correlation time and rows per coordinate, the held-out folds, the validation score; ``found``:
    the searched values and fits so far (the start of a combination's search, the chosen one's refit)."""

    logs: list
    geometry: Any
    options: dict
    steps: float
    reference: dict
    parts: int
    gap_s: float
    validation: Callable[[Any], float] | None
    found: dict = field(default_factory=dict)

    def score(self, model: ModelSpec, fit: ModelFit | None = None) -> ModelScore:
        """A candidate's fit (the paper's with the settings; an extension's without refusals, judged
        here: implausible values its ``error``, undetermined ones listed) and its scores."""
        settings = self.options["settings"]
        lenient = settings.replace(plausibility=False, unexcited="report", max_relative_std=math.inf)
        start = {k: v for found in self.found.values() for k, v in found[0].items()}
        try:
            fit = fit or model_identification(self.logs, self.geometry, model=model, keep_blocks=True, start=start,
                                              **{**self.options, "settings": lenient})
        except (UnidentifiableError, ImplausibleError) as exc:
            return ModelScore(model, error=str(exc))
        ident = fit.identification
        self.found[model] = ({n: v for n, v in searched_values(ident.model).items() if n in added_parameters(model)},
                             fit)
        error = rejected_extension(ident, settings.fit.plausibility)
        k = bic_parameter_count(model, ident)
        bic, j, _ = information_bic(ident.residual_ss, k, self.steps, self.reference)
        rss, rows = (sum(v) for v in zip(*ident.residual_ss.values()))
        refit = _refit(ident.model, self.geometry, self.options["fixed"], settings, self.options["estimator"],
                       ident.rows if ident.model.stribeck else None)
        held_out = holdout_parts(ident.blocks, refit, parts=self.parts, gap_s=self.gap_s)
        return ModelScore(model, ident.model, bic=bic, likelihood=j, k=k, residual_rms=math.sqrt(rss / rows),
                          nrmse_holdout=holdout_of_sums(held_out),
                          undetermined=_undetermined(model, ident, settings.fit.max_relative_std), error=error,
                          nrmse_validation=None if self.validation is None else float(self.validation(ident)),
                          fits=fit.fits + self.parts, identification=ident, residual_ss=dict(ident.residual_ss),
                          holdout_sums=held_out, correlation_steps=self.steps, reference_rows=self.reference,
                          columns={n: g for n, g in column_groups(ident.blocks, ident.model.linear_names).items()
                                   if n not in held_parameters(model, ident)})  # the columns k counts

    def final(self, score: ModelScore) -> ModelScore:
        """The chosen extension refitted with the settings (refusals as ``identify`` makes them), the
        search's std and warnings carried over."""
        if score.model.is_paper:
            return score
        from agvdyn.identification.pipeline import identify

        fit = self.found[score.model][1]
        ident = identify(self.logs, self.geometry, keep_blocks=True, model=score.fitted, **self.options)
        return dataclasses.replace(score, identification=with_searched(ident, fit.stds, fit.warnings, fit.spread),
                                   fits=score.fits + 1)


def compare_models(logs: Any, platform: Any = None, *, validation: Callable[[Any], float] | None = None,
                   fixed: Mapping[str, float] | None = None,
                   settings: IdentificationSettings = IdentificationSettings(), estimator: Any = None,
                   experiment: str = "auto", workers: int | None = None,
                   delay_range: tuple[float, float] = DELAY_RANGE, stribeck_range: tuple[float, float] = STRIBECK_RANGE,
                   parts: int = HOLDOUT_PARTS, rows: str = "evidence") -> ModelSelection:
    """Fit and score the paper's model, each extension alone and all together (:func:`candidate_models`;
    searches by :func:`.model_search.identify_model`), and choose as ``auto`` does (:func:`chosen_model`;
    a combination of several passing extensions is fitted when needed, its search started from theirs).
    Scores: see the module docstring. ``validation``: a score of a fit on logs it did not use (lower is
    better; e.g. the mean NRMSE of :func:`agvdyn.validation.validate` on a lane change). An extension
    is fitted without refusals and judged: implausible values are its ``error``, parameters the data
    do not determine its ``undetermined``; either keeps it from being chosen. The chosen one is
    refitted with ``settings`` (its identification is what ``identify_model`` of it gives). The paper
    model's refusal is raised. ``rows``: the rows two models are compared on (:func:`versus`: ``"evidence"``,
    like with like; ``"all"``). The other keywords are :func:`.pipeline.identify`'s."""
    from agvdyn.identification.pipeline import platform_for

    if rows not in ROWS_CHOICES:
        raise ValueError(f"rows={rows!r}: expected one of {list(ROWS_CHOICES)}")
    items = [logs] if isinstance(logs, (Log, LogFile)) else list(logs)
    items = [x.load() if isinstance(x, LogFile) and not x.long else x for x in items]  # read once, fitted often
    geometry = platform_for(items, platform)
    options = dict(fixed=DEFAULT_FIXED if fixed is None else fixed, settings=settings, estimator=estimator,
                   experiment=experiment, workers=workers)
    paper, *others = candidate_models(delay_range=delay_range, stribeck_range=stribeck_range)
    first = model_identification(items, geometry, model=paper, keep_blocks=True, **options)
    steps = correlation_steps(first.identification, lambda: search_fit(
        items, geometry, paper, settings, uncertainty="hac", **{k: v for k, v in options.items() if k != "settings"}))
    sample_time = min(float((x.first() if isinstance(x, LogFile) else x).sample_time) for x in items)
    reference = {g: n for g, (_, n) in first.identification.residual_ss.items()}
    scoring = _Scoring(items, geometry, options, steps, reference, parts, 2 * steps * sample_time, validation)
    scores = [scoring.score(paper, first)] + [scoring.score(m) for m in others[:-1]]
    scores.append(scoring.score(others[-1]))  # all together: its search starts from each one's alone
    while True:  # the choice refitted with the settings; refused there (as identify refuses): the next choice
        index, scores = chosen_model(scores, combine=scoring.score, rows=rows)
        try:
            scores[index] = scoring.final(scores[index])
            break
        except (UnidentifiableError, ImplausibleError) as exc:
            scores[index] = dataclasses.replace(scores[index], error=f"refused with the settings: {exc}")
    scores = [dataclasses.replace(s, chosen=k == index, versus_paper=None if k == 0 or s.error is not None
                                  else versus(s, scores[0], rows)) for k, s in enumerate(scores)]
    notes = tuple(w for s in scores[1:] if not s.chosen and s.versus_paper and s.model.extensions == ("delay",)
                  and (w := rows_disagree(s.label, versus(s, scores[0], "all"), s.versus_paper)))
    if notes:  # auto's choice carries it: the steering rows favour a delay the chassis rows do not confirm
        ident = scores[index].identification
        scores[index] = dataclasses.replace(scores[index], identification=dataclasses.replace(
            ident, warnings=ident.warnings + notes))
    return ModelSelection(tuple(scores), index, steps, sum(reference.values()) / steps, parts)
