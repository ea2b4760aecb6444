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
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.model_search import concentrated_likelihood, delay_evidence
from agvdyn.model_spec import ModelSpec

__all__ = ["comparison_note", "holdout_nrmse", "holdout_parts", "holdout_sums", "holdout_of_sums", "comparison_rows",
           "bic_on_rows", "ROWS_CHOICES", "HOLDOUT_PARTS"]

#: Parts of each segment in the held-out error's cross-validation.
HOLDOUT_PARTS = 4

#: How ``auto`` compares two models: on the evidence rows of their difference, or on all rows (the
#: rule before issue 30's delay fix; kept for the study's comparison).
ROWS_CHOICES = ("evidence", "all")

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


def comparison_rows(a: ModelSpec, b: ModelSpec, residual_ss: Mapping[str, tuple[float, int]]) -> tuple[str, ...] | None:
    """The coordinate groups (of ``residual_ss``) models ``a`` and ``b`` are compared on: the delay's
    evidence rows (:func:`.model_search.delay_evidence`) when the delay is all they differ in, else None
    (all rows)."""
    differ = set(a.extensions) ^ set(b.extensions)
    if differ != {"delay"}:
        return None
    return tuple(delay_evidence(residual_ss))


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
    (outside the part by more than ``gap_s``)."""
    first, length = span
    start, stop = first + fold * length, first + (fold + 1) * length
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

    def num(x: Any, fmt: str) -> str:
        return "-" if x is None or not math.isfinite(x) else format(x, fmt)

    return (f"against the paper's model on the {', '.join(versus['rows'])} rows: BIC {num(versus['bic'], '.1f')} "
            f"vs {num(versus['bic_other'], '.1f')}, held-out {num(versus['nrmse_holdout'], '.4g')} vs "
            f"{num(versus['nrmse_holdout_other'], '.4g')}")
