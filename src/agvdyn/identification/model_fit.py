"""The model extensions in the regression's result (issue 30; names and laws of :mod:`agvdyn.model_spec`).

A resolved :class:`~agvdyn.model_spec.ModelSpec` adds the columns ``linear_names`` after the paper's
eleven and the offsets (:mod:`.model_rows`). Their values become the extensions' parameters:

* ``d_sl, d_sr, d_sw``: the breakaway levels, estimated directly (their columns ``H_k^T [e tanh]``);
* ``x_c, y_c``: the columns estimate ``m_ch x_c`` and ``m_ch y_c``; ``y_c = (m_ch y_c) / m_ch`` with the
  delta-method std ``sqrt(g^T V g)``, ``g = (1 / m_ch, -(m_ch y_c) / m_ch^2)`` and V the covariance of
  the two columns (m_ch fixed: its variance 0); ``inf`` where either is undetermined. x_c no motion
  mode sees (:data:`UNOBSERVABLE`): it is held at 0, std ``inf``;
* ``w_sl, w_sr, w_sw``: the Stribeck velocities the spec gives (not estimated here: no std).

:func:`residual_sums` is the residual sum of squares and the rows of each coordinate group (the
profile of a searched nonlinear value, BIC).
"""
from __future__ import annotations

from typing import Any

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from agvdyn.identification.excitation import ExcitationCheck
from agvdyn.identification.normal import RegressionData
from agvdyn.identification.plausibility import implausible_parameters
from agvdyn.identification.regression import Dependency
from agvdyn.model_spec import BREAKAWAY_NAMES, CENTRE_NAMES, FRICTION_GROUPS, STRIBECK_NAMES, ModelSpec
from agvdyn.platform import PARAMETER_NAMES, Geometry, Parameters

__all__ = ["UNOBSERVABLE", "hold_unobservable", "tie_unsupported", "with_unobservable", "extension_estimates",
           "breakaway_warnings", "unsupported_breakaway", "held_parameters", "held_reason", "MIN_SUPPORT_ROWS",
           "noisy_extensions", "residual_sums", "linear_values", "rejected_extension"]


#: The model's columns no data determine, and why: held at 0 with an unbounded interval and a warning,
#: never refused (no experiment excites them).
UNOBSERVABLE = {
    "x_c": "x_c is not seen by the drive torques in any motion mode: with the steering mirrored front and rear the "
           "reference point never moves sideways (car-like: w = kappa v_x, a_y = v_x w), so m_ch x_c drops out of "
           "every projected row (the rolling constraints carry its centripetal force) and only adds m_ch x_c^2 to "
           "C_ch; held at 0, 95 % interval unbounded (y_c is seen in car-like turns)",
}


def hold_unobservable(data: RegressionData, free: Sequence[str], model: ModelSpec
                      ) -> tuple[RegressionData, list[str], dict[str, str]]:
    """``data`` and ``free`` with the model's unobservable columns (:data:`UNOBSERVABLE`) held at 0, and
    those columns with why."""
    unseen = {n: why for n, why in UNOBSERVABLE.items() if n in model.linear_names and n in free}
    if not unseen:
        return data, list(free), {}
    held = [list(free).index(n) for n in unseen]
    return data.holding(held, np.zeros(len(held))), [n for n in free if n not in unseen], unseen


def tie_unsupported(data: RegressionData, free: Sequence[str], unsupported: Mapping[str, str]
                    ) -> tuple[RegressionData, list[str]]:
    """``data`` and ``free`` with the breakaway levels ``unsupported`` (:func:`unsupported_breakaway`) held at the
    paper's law ``d_s = d_c``: each level's column joins its group's ``d_c`` column (``H^T [(1 - e) tanh] +
    H^T [e tanh] = H^T tanh``, the paper's) and leaves the regression; with ``d_c`` fixed, the level is held
    at its value."""
    free = list(free)
    tied = [(n, FRICTION_GROUPS[n[-1]][1]) for n in BREAKAWAY_NAMES if n in unsupported and n in free]
    joined = [(free.index(n), free.index(c)) for n, c in tied if c in free]
    held = [n for n, c in tied if c not in free]
    if joined:
        data = data.tying([c for c, _ in joined], [t for _, t in joined])
    names = [n for n in free if n not in {n for n, c in tied if c in free}]
    if held:
        values = [data.theta_fixed[PARAMETER_NAMES.index(FRICTION_GROUPS[n[-1]][1])] for n in held]
        data = data.holding([names.index(n) for n in held], np.array(values))
        names = [n for n in names if n not in held]
    return data, names


def with_unobservable(check: ExcitationCheck, unseen: Mapping[str, str]) -> ExcitationCheck:
    """The excitation check with the held unobservable columns among the held and unbounded ones, warned."""
    if not unseen:
        return check
    return dataclasses.replace(check, held={**dict.fromkeys(unseen, 0.0), **check.held},
                               unbounded=check.unbounded | frozenset(unseen),
                               warnings=tuple(f"not identifiable: {why}" for why in unseen.values()) + check.warnings)


def extension_estimates(model: ModelSpec, names: Sequence[str], theta: np.ndarray, free: Sequence[str],
                        cov: np.ndarray, std: Mapping[str, float]) -> tuple[dict[str, float], dict[str, float]]:
    """``(extra, extra_std)`` of the model's parameters from the regression: ``theta`` every column's
    value (``names``), ``cov`` the covariance of the ``free`` columns, ``std`` their std (``inf``:
    undetermined, also for held columns)."""
    extra: dict[str, float] = {}
    extra_std: dict[str, float] = {}
    value = dict(zip(names, np.asarray(theta, dtype=float).tolist()))
    for name in BREAKAWAY_NAMES if model.stribeck else ():
        extra[name] = value[name]
        extra_std[name] = std.get(name, math.inf)
    if model.stribeck:
        extra.update(zip(STRIBECK_NAMES, model.stribeck_velocities))
    if model.com_offset:
        m = value["m_ch"]
        for name in CENTRE_NAMES:  # m_ch held at 0 (no chassis rows): no offset to speak of
            extra[name] = value[name] / m if m != 0 else 0.0
            extra_std[name] = _ratio_std(name, value[name], m, free, cov, std) if m != 0 else math.inf
    return extra, extra_std


def _ratio_std(name: str, a: float, m: float, free: Sequence[str], cov: np.ndarray,
               std: Mapping[str, float]) -> float:
    """Delta-method std of ``a / m`` (``a`` the column ``name``, ``m`` = m_ch); inf where either is undetermined."""
    free = list(free)
    if name not in free or not math.isfinite(std.get(name, math.inf)):
        return math.inf
    if "m_ch" in free and not math.isfinite(std.get("m_ch", math.inf)):
        return math.inf
    cols = [free.index(name)] + ([free.index("m_ch")] if "m_ch" in free else [])
    g = np.array([1.0 / m, -a / m**2])[:len(cols)]
    var = float(g @ cov[np.ix_(cols, cols)] @ g)
    return math.sqrt(var) if var >= 0 and math.isfinite(var) else math.inf


def linear_values(model: ModelSpec, extra: Mapping[str, float], parameters: Parameters) -> np.ndarray | None:
    """The values of the model's regression columns (``linear_names``: ``d_s`` as they are, ``m_ch x_c``,
    ``m_ch y_c``) from its parameters; None for a model without columns."""
    if not model.linear_names:
        return None
    return np.array([extra[n] * parameters.m_ch if n in CENTRE_NAMES else extra[n] for n in model.linear_names])


#: Used rows of a joint group within its Stribeck range (:func:`.model_rows.stribeck_support`) below which
#: its breakaway level is not determined: 1 s at the paper's 2 ms.
MIN_SUPPORT_ROWS = 500


def unsupported_breakaway(model: ModelSpec, support: Mapping[str, int]) -> dict[str, str]:
    """The breakaway levels the rows cannot show, with why: groups with fewer than :data:`MIN_SUPPORT_ROWS`
    used rows in their Stribeck range (``support``, counted by the row pass; empty: not counted, nothing
    judged), and the levels the model holds (``ModelSpec.held``). A group's column without rows holds only
    the filter's tails of stick phases (a passive steering sticks at every reversal and crosses the range
    within milliseconds): a number fitted there is not a breakaway level. They are held at the paper's law
    (``d_s = d_c``, :func:`tie_unsupported`) and reported with an unbounded interval."""
    if not model.stribeck:
        return {}
    out = {n: held_reason(n) for n in model.held}
    if not support:
        return out
    for g, w_s in zip("lrw", model.stribeck_velocities):
        n = int(support.get(g, 0))
        if n < MIN_SUPPORT_ROWS and f"d_s{g}" not in out:
            out[f"d_s{g}"] = (f"d_s{g} not determined: {n} used rows of the {_GROUP_NAMES[g]} run in its Stribeck range "
                              f"(|rate| < {0.83 * w_s:.3g} rad/s, needs {MIN_SUPPORT_ROWS}); its column holds only the "
                              "filter's tails of stick phases. Held at the paper's law d_s = d_c (its column joins "
                              "d_c's), interval unbounded (slow steady motion of that joint would show it)")
    return out


_GROUP_NAMES = {"l": "left steering", "r": "right steering", "w": "wheels"}


def held_reason(name: str) -> str:
    """The warning of a breakaway level the model holds (``ModelSpec.held``)."""
    return f"{name} held at the paper's law d_s = d_c (the model's held levels): not estimated, interval unbounded"


def held_parameters(model: ModelSpec, ident: Any) -> tuple[str, ...]:
    """The parameters of ``model`` a fit reports without estimating them (unbounded by design, not for
    want of data in this log): those no motion mode of the vehicle shows (:data:`UNOBSERVABLE`: x_c)
    and the breakaway levels of groups without rows in their Stribeck range (:func:`unsupported_breakaway`,
    at the paper's law). Model selection neither counts them as parameters nor lets them keep a model
    from being chosen."""
    held = tuple(n for n in UNOBSERVABLE if n in model.linear_names)
    return held + tuple(unsupported_breakaway(ident.model, ident.rows.stribeck_support))


def breakaway_warnings(extra: Mapping[str, float], extra_std: Mapping[str, float], parameters: Parameters,
                       significance: float = 2.0) -> list[str]:
    """A breakaway level below its group's sliding Coulomb level by more than ``significance`` of its std
    (allowed: the data say so) named."""
    out = []
    for name in BREAKAWAY_NAMES:
        if name not in extra:
            continue
        coulomb = FRICTION_GROUPS[name[-1]][1]
        level = getattr(parameters, coulomb)
        sd = extra_std.get(name, math.inf)
        if level - extra[name] > significance * sd:
            out.append(f"{name} = {extra[name]:.4g} N m (std {sd:.2g}) is below the sliding level {coulomb} = "
                       f"{level:.4g} N m by more than {significance:g} std: no breakaway in these data (friction "
                       "lower at low rates than sliding); the paper's friction law may do")
    return out


def noisy_extensions(check: ExcitationCheck, coef: np.ndarray, std: Mapping[str, float], limit: float,
                     geometry: Geometry | None) -> list[Dependency]:
    """The model's columns the data hardly determine: a breakaway level whose std exceeds ``limit``
    times its value (as the paper's parameters), a centre-of-mass offset whose std exceeds the
    platform's half-diagonal (its value may well be 0: the vehicle's size is the scale)."""
    free = list(check.free)
    value = dict(zip(free, np.asarray(coef, dtype=float).tolist()))
    out = []
    for n in (x for x in BREAKAWAY_NAMES if x in value and x not in check.unbounded):
        if std[n] > limit * abs(value[n]):
            out.append(Dependency(n, (), math.nan, relative_std=float(std[n] / abs(value[n]))))
    centre = [x for x in CENTRE_NAMES if x in value and x not in check.unbounded]
    if centre and geometry is not None:
        m_ch = abs(check.data.theta(np.asarray(coef, dtype=float))[PARAMETER_NAMES.index("m_ch")])
        half = math.hypot(geometry.l, geometry.b) / 2
        for n in centre:
            if std[n] > half * m_ch:
                out.append(Dependency(n, (), math.nan, relative_std=float(std[n] / (half * m_ch)),
                                      scale=f"the platform's half-diagonal ({half:.3g} m)"))
    return out


def residual_sums(data: RegressionData, coef: np.ndarray) -> dict[str, tuple[float, int]]:
    """``{coordinate group: (residual sum of squares, rows)}`` over the stacked rows of the regression
    (unweighted; from the stored rows, else the pseudo-rows of each key)."""
    if data.store is not None:
        rss = data.group_rss(coef)
    else:
        rss = np.zeros(len(data.group_names))
        x = np.append(np.asarray(coef, dtype=float), -1.0)
        for key, P in zip(data.keys, data.key_pseudo):
            r = P @ x
            rss[data.group_names.index(key[1])] += float(r @ r)
    return {name: (float(rss[i]), int(data.group_rows[i])) for i, name in enumerate(data.group_names)}


def rejected_extension(ident: Any, plausibility: bool) -> str | None:
    """Why an extension's fit cannot be kept: physically impossible values (``plausibility``,
    :func:`.plausibility.implausible_parameters`), or breakaway levels below their sliding level by
    more than 2 std (:func:`breakaway_warnings`: the Stribeck law then describes friction
    that drops at low rates, no breakaway); None."""
    values = {**{n: getattr(ident.parameters, n) for n in ident.std},
              **{n: v for n, v in ident.extra.items() if n in BREAKAWAY_NAMES}}
    refused = implausible_parameters(values, {**ident.std, **ident.extra_std})[0] if plausibility else []
    if refused:
        return "physically impossible estimates: " + ", ".join(f"{r.name} = {r.value:.4g} +- {r.std:.2g}"
                                                                for r in refused)
    below = breakaway_warnings(ident.extra, ident.extra_std, ident.parameters)
    return None if not below else "no breakaway: " + "; ".join(w.split(": no breakaway")[0] for w in below)
