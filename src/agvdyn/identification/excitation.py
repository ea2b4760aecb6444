"""Step 1 of the regression (:mod:`.fit`): rank and excitation. Which free parameters the rows
do not determine (the QR rank test, sec. 6.1), which are held for ``unexcited="report"``, and which
are poorly conditioned (variance inflation) and whether the data still determine them (their
predicted std); :class:`ExcitationCheck` is what the estimate step takes. The pre-flight check
(:func:`agvdyn.preflight.preflight`) rates the excitation with the same functions.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from agvdyn.determinacy import std_from_information
from agvdyn.identification.normal import RegressionData
from agvdyn.identification.regression import (
    Dependency,
    Estimator,
    UnidentifiableError,
    dependent_parameters,
    variance_inflation,
)
from agvdyn.identification.settings import IdentificationSettings
from agvdyn.platform import PARAMETER_NAMES

__all__ = ["COLLINEAR_RELATIVE_STD", "ExcitationCheck", "check_excitation", "predicted_relative_std",
           "collinear_warnings"]


@dataclass(frozen=True, eq=False)
class ExcitationCheck:
    """What the rank and excitation step leaves for the estimate: ``data`` (unexcited parameters
    held, with ``unexcited="report"``; the stored rows themselves for an estimator that weighs
    single rows), the ``free`` parameters left, the ``held`` ones and their values, the
    ``unbounded`` ones (held, or dependent on a held one: 95 % interval unbounded), the poorly
    conditioned ones (``collinear``) and the warnings so far."""

    data: RegressionData
    free: tuple[str, ...]
    held: Mapping[str, float]
    unbounded: frozenset[str]
    collinear: tuple[Dependency, ...]
    warnings: tuple[str, ...]


def check_excitation(data: RegressionData, free: Sequence[str], estimator: Estimator,
                     settings: IdentificationSettings) -> ExcitationCheck:
    """Step 1: enough rows, the rank test naming what is not excited (raised, or held with
    ``unexcited="report"``), the variance inflation of each parameter."""
    free = list(free)
    if data.pseudo and getattr(estimator, "needs_rows", False):  # robust weighs single rows: read them back
        data = data.stacked()
    if data.n_rows <= len(free):
        raise UnidentifiableError(
            [Dependency(n, (), 0.0) for n in free],
            f"{data.n_rows} equation rows left after the stiction mask for {len(free)} parameters; ")
    missing = dependent_parameters(data.A, free, tolerance=settings.fit.rank_tolerance)
    unbounded: set[str] = set()
    hold: dict[str, float] = {}
    warnings: list[str] = []
    if missing and not settings.fit.reports_unexcited:
        raise UnidentifiableError(missing)
    if missing:  # held at zero (bounded: their lower bound); they and their group get unbounded intervals
        unbounded, hold, warnings = _unexcited(missing, free, estimator)
        data = data.holding([free.index(n) for n in hold], np.array(list(hold.values())))
        free = [n for n in free if n not in hold]
    inflation = variance_inflation(data.A)
    collinear = [Dependency(n, (), math.nan, inflation=float(v)) for n, v in zip(free, inflation)
                 if v > settings.fit.max_inflation and n in PARAMETER_NAMES]
    return ExcitationCheck(data, tuple(free), hold, frozenset(unbounded), tuple(collinear), tuple(warnings))


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


def collinear_warnings(collinear: Sequence[Dependency], data: RegressionData, coef: np.ndarray,
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
