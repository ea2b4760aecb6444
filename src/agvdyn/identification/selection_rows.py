"""The rows two candidate models are compared on (issue 30, :mod:`.selection`): like with like.

A comparison asks whether one model explains the data better than another. Where the two differ only
by a torque delay, the evidence is on the rows the delay's search uses (:func:`.model_search.delay_evidence`:
the chassis rows); the steering rows of a passively steered vehicle carry the steering joints'
stick-slip, which the tanh law lacks and which looks like a torque *lead* (-6 to -7 ms on our plant's
effect-free logs, 10 seeds, where the chassis rows put it at -1 to +3 ms). Summed over all rows, that
misfit outvotes a delay the chassis rows see (seed 1, 6 ms: the chassis rows' J falls by 7.2 tau, the
steering rows' rises by 52 tau). So both models are scored on the same rows, the evidence rows of the
extensions in which they differ (all rows as soon as one of those is not the delay alone), with the same
BIC and held-out error as on all rows: ``BIC_G = J_G / tau + k log(N_G / tau)`` (J, N over the coordinate
groups G; tau and the reference rows the paper model's) and the held-out NRMSE averaged over the
``segment:coordinate`` keys of G.

The breakaway levels likewise (:data:`BREAKAWAY_EVIDENCE`): a steering group's on its own coordinate's rows,
the wheels' on the chassis rows; a group whose level the fit could not determine (no rows in its
Stribeck range, :func:`.model_fit.unsupported_breakaway`) gives none. On our plant's effect-free logs
the Stribeck model's gain is all on the steering rows (seed 3: J/tau -19.5 alpha_l, -31.3 alpha_r,
+0.1 chassis), made by the steering groups' columns whose levels it reports as undetermined (their
columns fit the filter's tails of the steering joints' stick phases); those levels are now held at the
paper's law in the fit (:func:`.model_fit.tie_unsupported`). The BIC counts every fitted column and
searched value (:func:`bic_parameter_count`); on some coordinate groups only those with an entry on their
rows (:func:`rows_parameter_count`): the likelihood of those rows depends on no other.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.model_fit import UNOBSERVABLE, unsupported_breakaway
from agvdyn.identification.model_search import DELAY, concentrated_likelihood, delay_evidence
from agvdyn.identification.settings import CHASSIS_COORDINATES
from agvdyn.model_spec import STRIBECK_NAMES, ModelSpec

__all__ = ["comparison_note", "holdout_nrmse", "holdout_parts", "holdout_sums", "holdout_of_sums", "comparison_rows",
           "bic_on_rows", "bic_parameter_count", "rows_parameter_count", "column_groups", "breakaway_evidence",
           "determined_breakaway", "rows_disagree", "ROWS_CHOICES", "HOLDOUT_PARTS", "BREAKAWAY_EVIDENCE", "GAP_PART_FRACTION"]

#: Parts of each segment in the held-out error's cross-validation.
HOLDOUT_PARTS = 4

#: The largest gap (a fraction of the held part's length) between a held part and the training rows of its
#: segment: with a correlation time of seconds (car-like logs: 3,500-9,900 steps, a gap of 15-40 s) the
#: gap ``2 tau`` would take whole segments out of the training, and each fold's fit would extrapolate.
GAP_PART_FRACTION = 0.5

#: How ``auto`` compares two models: on the evidence rows of their difference, or on all rows (the
#: rule before issue 30's delay fix; kept for the study's comparison).
ROWS_CHOICES = ("evidence", "all")

#: The coordinate groups whose rows are the evidence of each friction group's breakaway level: a steering
#: joint's own coordinate (``alpha_v``: both follow it in car-like turns), the wheels' the chassis
#: coordinates (the steering rows carry the steering joints' stick-slip, as for the delay).
BREAKAWAY_EVIDENCE = {"l": ("alpha_l", "alpha_v"), "r": ("alpha_r", "alpha_v"), "w": CHASSIS_COORDINATES}

#: A predictor of a block's model torques (n, n_k) made by a refit on blocks.
Refit = Callable[[Sequence[EquationBlock]], Callable[[EquationBlock], np.ndarray]]


def holdout_sums(blocks: Sequence[EquationBlock], refit: Refit, folds: Sequence[Sequence[tuple[np.ndarray, np.ndarray]]]
                 ) -> dict[str, tuple[float, float]]:
    """``{segment:coordinate: (sum of squared prediction errors, sum of squared measured torques)}``
    over the held-out rows of every fold: ``folds[j][i]`` the (held, training) row masks of block i in
    fold j; ``refit`` on the training rows predicts the held ones (kept rows only)."""
    sums: dict[str, list[float]] = {}
    for masks in folds:
        train = [b.with_keep(b.keep & use[:, None]) for b, (_, use) in zip(blocks, masks)]
        predict = refit([b for b in train if b.keep.any()])
        for b, (held, _) in zip(blocks, masks):
            rows = b.keep & held[:, None]
            if not rows.any():
                continue
            model = predict(b)
            for j, coordinate in enumerate(b.coordinates):
                r = rows[:, j]
                entry = sums.setdefault(f"{b.segment}:{coordinate}", [0.0, 0.0])
                entry[0] += float(np.sum((b.torque[r, j] - model[r, j]) ** 2))
                entry[1] += float(np.sum(b.torque[r, j] ** 2))
    return {k: (e, m) for k, (e, m) in sums.items()}


def holdout_of_sums(sums: Mapping[str, tuple[float, float]], groups: Sequence[str] | None = None) -> float:
    """The held-out NRMSE ``sqrt(error / measured)`` of each ``segment:coordinate`` key (of a coordinate in
    ``groups``; all when None), averaged over the keys; NaN when no key has a measured torque."""
    scores = [math.sqrt(e / m) for k, (e, m) in sums.items()
              if m > 0 and (groups is None or k.rsplit(":", 1)[-1] in groups)]
    return float(np.mean(scores)) if scores else math.nan


def comparison_rows(a: ModelSpec, b: ModelSpec, residual_ss: Mapping[str, tuple[float, int]],
                    breakaway_groups: Sequence[str] | None = None) -> tuple[str, ...] | None:
    """The coordinate groups (of ``residual_ss``) models ``a`` and ``b`` are compared on: the evidence
    rows of the extensions they differ in -- the delay's (:func:`.model_search.delay_evidence`), the
    breakaway levels' of the friction groups ``breakaway_groups`` (:func:`breakaway_evidence`; None:
    all three) --; None (all rows) when they differ in the centre of mass, or when a difference of the
    friction law has evidence on every row. ``()``: a friction law without evidence (no group determined)."""
    differ = set(a.extensions) ^ set(b.extensions)
    if differ == {"delay"}:
        return tuple(delay_evidence(residual_ss))
    if not differ or "com_offset" in differ:
        return None
    rows = set(breakaway_evidence(residual_ss, "lrw" if breakaway_groups is None else breakaway_groups))
    if "delay" in differ and rows:
        rows |= set(delay_evidence(residual_ss))
    return None if rows >= set(residual_ss) else tuple(g for g in residual_ss if g in rows)


def breakaway_evidence(residual_ss: Mapping[str, tuple[float, int]], groups: Sequence[str]
                       ) -> Mapping[str, tuple[float, int]]:
    """The coordinate groups of ``residual_ss`` that are the evidence of the breakaway levels of the friction
    ``groups`` (``l``, ``r``, ``w``; :data:`BREAKAWAY_EVIDENCE`); empty without groups."""
    unknown = [g for g in groups if g not in BREAKAWAY_EVIDENCE]
    if unknown:
        raise ValueError(f"breakaway_groups={list(groups)}: expected friction groups among {list(BREAKAWAY_EVIDENCE)}")
    wanted = {c for g in groups for c in BREAKAWAY_EVIDENCE[g]}
    return {c: v for c, v in residual_ss.items() if c in wanted}


def determined_breakaway(ident: Any) -> tuple[str, ...] | None:
    """The friction groups (``l``, ``r``, ``w``) whose breakaway level a Stribeck fit ``ident`` determined: those
    with rows in their Stribeck range (not :func:`.model_fit.unsupported_breakaway`); None without a fit or its
    rows' account (unknown), ``()`` for a model without the Stribeck law."""
    model = getattr(ident, "model", None)
    support = getattr(getattr(ident, "rows", None), "stribeck_support", None)
    if model is None or support is None:
        return None
    if not model.stribeck:
        return ()
    unsupported = unsupported_breakaway(model, support)
    return tuple(g for g in "lrw" if f"d_s{g}" not in unsupported)


def bic_parameter_count(model: ModelSpec, ident: Any) -> int:
    """``k`` of the BIC of a fit ``ident`` of ``model``: every column the regression estimated (the paper's free
    parameters, the torque offsets, the model's columns but those held at 0 by design, :data:`.model_fit.UNOBSERVABLE`)
    and every searched value (the delay, the Stribeck velocities). A breakaway level without rows in its Stribeck
    range is held at the paper's law in the fit (:func:`.model_fit.tie_unsupported`): neither it nor its searched
    velocity counts (the model does not depend on that velocity)."""
    held = set(unsupported_breakaway(ident.model, ident.rows.stribeck_support)) if ident.model.stribeck else set()
    columns = [n for n in ident.model.linear_names if n not in UNOBSERVABLE and n not in held]
    searched = ((DELAY,) if model.delay == "auto" else ()) + tuple(
        n for n in (STRIBECK_NAMES if model.stribeck and model.stribeck_velocities is None else ())
        if f"d_s{n[-1]}" not in held)
    return len(ident.std) + len(ident.offsets_std) + len(columns) + len(searched)


def column_groups(blocks: Sequence[EquationBlock], names: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Per model column (``names``: a model's ``linear_names``, the order of the blocks' ``model_regressor``)
    the coordinate groups on whose kept rows it has a nonzero entry. A steering group's breakaway column is
    structurally zero on the chassis rows (and ``m_ch x_c``, ``m_ch y_c`` outside car-like turns)."""
    seen: dict[str, set[str]] = {n: set() for n in names}
    for b in blocks:
        if b.model_regressor is None or b.model_regressor.shape[-1] != len(names):
            continue
        for j, coordinate in enumerate(b.coordinates):
            rows = b.keep[:, j]
            if rows.any():
                for n in np.asarray(names)[np.any(b.model_regressor[rows, j, :] != 0, axis=0)]:
                    seen[str(n)].add(coordinate)
    return {n: tuple(sorted(g)) for n, g in seen.items()}


def rows_parameter_count(k: int, model: ModelSpec, columns: Mapping[str, Sequence[str]],
                         groups: Sequence[str] | None) -> int:
    """``k`` of a fit (:func:`bic_parameter_count`) on the coordinate groups ``groups`` (all when None): less the
    model's columns without an entry on their rows (``columns``: :func:`column_groups` of the columns ``k``
    counts; held ones, x_c and levels at the paper's law, are not in ``k`` and must not be in ``columns``) and
    the searched Stribeck velocity of each such breakaway level -- parameters the likelihood of those rows does
    not depend on (a steering group's breakaway level and velocity on the chassis rows). Without ``columns``
    (no blocks kept): ``k``."""
    if groups is None or not columns:
        return k
    off = [n for n, where in columns.items() if n not in UNOBSERVABLE and not set(where) & set(groups)]
    searched = model.stribeck and model.stribeck_velocities is None
    velocities = [f"w_s{n[-1]}" for n in off if searched and n.startswith("d_s")]
    return k - len(off) - len(velocities)


def bic_on_rows(residual_ss: Mapping[str, tuple[float, int]], k: int, correlation_steps: float,
                reference_rows: Mapping[str, int], groups: Sequence[str] | None) -> float:
    """``J_G / tau + k log(N_G / tau)`` over the coordinate groups ``groups`` (all when None): J of each
    group's mean square times its ``reference_rows`` (:func:`.model_search.concentrated_likelihood`)."""
    if not (correlation_steps >= 1 and math.isfinite(correlation_steps)):
        raise ValueError(f"correlation_steps={correlation_steps!r}: expected a finite number >= 1 (steps)")
    chosen = {g: v for g, v in residual_ss.items() if groups is None or g in groups}
    if not chosen:
        raise ValueError(f"groups={list(groups or ())}: none of the fit's coordinate groups {list(residual_ss)}")
    rows = {g: reference_rows.get(g, n) for g, (_, n) in chosen.items()}
    j = concentrated_likelihood(chosen, rows)
    return j / correlation_steps + k * math.log(sum(rows.values()) / correlation_steps)


def _parts(blocks: Sequence[EquationBlock], parts: int) -> dict[tuple[str, str], tuple[float, float]]:
    """Per (source, segment): its first time and the length of each of its ``parts`` parts."""
    span: dict[tuple[str, str], list[float]] = {}
    for b in blocks:
        if b.t.size:
            lo, hi = span.setdefault((b.source, b.segment), [math.inf, -math.inf])
            span[(b.source, b.segment)] = [min(lo, float(b.t[0])), max(hi, float(b.t[-1]))]
    return {key: (lo, max(hi - lo, 1e-12) * (1 + 1e-9) / parts) for key, (lo, hi) in span.items()}


def _fold_masks(b: EquationBlock, span: tuple[float, float], fold: int, gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Rows of block ``b`` (n,) in part ``fold`` of its segment, and those the training may use
    (outside the part by more than ``gap_s``, at most :data:`GAP_PART_FRACTION` of the part's length)."""
    first, length = span
    start, stop = first + fold * length, first + (fold + 1) * length
    gap_s = min(gap_s, GAP_PART_FRACTION * length)
    held = (b.t >= start) & (b.t < stop)
    distance = np.maximum(np.maximum(start - b.t, b.t - stop), 0.0)
    return held, ~held & (distance > gap_s)


def holdout_nrmse(blocks: Sequence[EquationBlock], refit: Refit, *, parts: int = HOLDOUT_PARTS,
                  gap_s: float = 0.0) -> float:
    """Held-out NRMSE by leave-one-part-out (see the module docstring): ``refit`` on the kept rows
    outside part j (and more than ``gap_s`` seconds from it) returns a predictor of a block's model
    torques; the NRMSE of the kept rows of part j is pooled per ``segment:coordinate`` over the
    folds and averaged over the keys. NaN when no key has a measured torque."""
    return holdout_of_sums(holdout_parts(blocks, refit, parts=parts, gap_s=gap_s))


def holdout_parts(blocks: Sequence[EquationBlock], refit: Refit, *, parts: int = HOLDOUT_PARTS,
                  gap_s: float = 0.0) -> dict[str, tuple[float, float]]:
    """The held-out error's sums per ``segment:coordinate`` (:func:`.selection_rows.holdout_sums`) of
    :func:`holdout_nrmse`'s folds."""
    if isinstance(parts, bool) or not isinstance(parts, int) or parts < 2:
        raise ValueError(f"parts={parts!r}: expected an integer >= 2 (parts of each segment held out in turn)")
    spans = _parts(blocks, parts)
    folds = [[_fold_masks(b, spans[(b.source, b.segment)], fold, gap_s) for b in blocks] for fold in range(parts)]
    return holdout_sums(blocks, refit, folds)


def comparison_note(versus: Mapping[str, Any] | None) -> str:
    """The comparison with the paper's model as a sentence when it was made on some rows only ("" on
    all rows or without one): its rows, both BICs and held-out errors (``ModelScore.versus_paper``)."""
    if not versus or versus.get("rows") == "all":
        return ""
    if not versus["rows"]:
        return "not compared with the paper's model: no rows are evidence of its breakaway levels (none determined)"

    def num(x: Any, fmt: str) -> str:
        return "-" if x is None or not math.isfinite(x) else format(x, fmt)

    valid = ("" if versus.get("nrmse_validation") is None or versus.get("nrmse_validation_other") is None else
             f", validation {num(versus['nrmse_validation'], '.4g')} vs {num(versus['nrmse_validation_other'], '.4g')}")
    return (f"against the paper's model on the {', '.join(versus['rows'])} rows: BIC {num(versus['bic'], '.1f')} "
            f"vs {num(versus['bic_other'], '.1f')}, held-out {num(versus['nrmse_holdout'], '.4g')} vs "
            f"{num(versus['nrmse_holdout_other'], '.4g')}{valid}")


def rows_disagree(label: str, all_rows: Mapping[str, Any], evidence: Mapping[str, Any] | None) -> str | None:
    """A warning when an extension (``compare_models``: the delay) lowers the BIC and the held-out error of
    the paper's model on all rows but not on its evidence rows (:func:`comparison_rows`; ``versus`` dicts of
    both), else None: ``auto`` keeps the paper's model there, and the rows it did not judge by favour the
    extension. (Not for the Stribeck law: its all-row gain is the undetermined steering levels' columns.)"""
    if not all_rows.get("better") or not evidence or evidence.get("rows") == "all" or evidence.get("better"):
        return None
    return (f"auto: {label} lowers the BIC ({all_rows['bic']:.1f} vs {all_rows['bic_other']:.1f}) and the held-out "
            f"error on all rows, not on its evidence rows ({', '.join(evidence['rows'])}: BIC {evidence['bic']:.1f} "
            f"vs {evidence['bic_other']:.1f}), so it is not kept. The other rows favour it: where the steering joints "
            "stick and slip, their rows read as a torque lead or lag; if your vehicle's steering friction does not, "
            f"fit --model with {label} and compare (docs/identification.md, \"Like with like\")")
