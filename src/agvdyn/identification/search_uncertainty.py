"""The searched values' uncertainty carried into the estimated parameters (issue 30).

The final fit of a model with a searched delay or Stribeck velocity is linear in its parameters at the
searched value ``x``: its std are conditional on ``x``. The estimates move with ``x`` (a 6 ms delay
taken for 0 moves C_l by -7 %), so the std of a parameter ``p`` given the search is

    std(p)^2 = std(p | x)^2 + spread(p)^2,   spread(p) = max(|p(x_lo) - p(x)|, |p(x_hi) - p(x)|)

with ``(x_lo, x_hi)`` the searched value's 68 % profile interval (:func:`.model_search.searched_intervals`)
clipped to its search range: an end where the profile does not rise enough within the range is the
range's bound (the user's range is all the data leave). One value-only fit at each end
(:func:`.model_search.search_fit`: the final fit's values at ``x``, no refusals), against the final fit's
values; several searched values add their spreads' squares. The
correlation matrix gets ``v v^T`` per searched value (``v``: the spread, signed by the central
difference). A std that then exceeds ``max_relative_std`` of its value (a centre-of-mass offset: the
platform's half-diagonal) is refused by name, as the fit refuses one (``unexcited="report"``: a warning).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from agvdyn.identification.regression import Dependency, UnidentifiableError
from agvdyn.identification.result import ParameterCorrelation
from agvdyn.model_spec import CENTRE_NAMES, STRIBECK_NAMES

__all__ = ["SearchSpread", "searched_spread", "with_spread"]


@dataclasses.dataclass(frozen=True)
class SearchSpread:
    """Per searched value (``delay_s``, ``w_s*``) the signed spread of each estimated parameter
    (``{searched: {parameter: spread}}``, the parameter's unit) and the fits made."""

    spread: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    fits: int = 0

    def std(self) -> dict[str, float]:
        """The std each parameter gains from the searches (root sum of squares over the searched values)."""
        out: dict[str, float] = {}
        for per in self.spread.values():
            for n, v in per.items():
                out[n] = math.hypot(out.get(n, 0.0), v)
        return out


def _estimates(ident: Any, names: tuple[str, ...]) -> dict[str, float]:
    return {n: float(ident.extra[n] if n in ident.extra else getattr(ident.parameters, n)) for n in names}


def searched_spread(ident: Any, values: Mapping[str, float], intervals: Mapping[str, tuple[float, float]],
                    bounds: Mapping[str, tuple[float, float]], fit_at: Callable[[dict[str, float]], Any]
                    ) -> SearchSpread:
    """The spread of ``ident``'s estimated parameters (finite std; the searched values themselves left
    out) over each searched value's interval (``intervals``, clipped to ``bounds``; see the module
    docstring), ``ident`` the fit at ``values``. ``fit_at(values)``: a value-only fit with the searched
    values ``values``."""
    names = tuple(n for n, s in {**ident.std, **ident.extra_std}.items()
                  if math.isfinite(s) and n not in STRIBECK_NAMES)
    if not names or not intervals:
        return SearchSpread()
    centre = _estimates(ident, names)
    fits, spread = 0, {}
    for name, (lo, hi) in intervals.items():
        x, (b_lo, b_hi) = values[name], bounds[name]
        ends = [min(max(e, b_lo), b_hi) for e in (lo, hi)]
        moved = []
        for end in ends:
            if abs(end - x) <= 1e-12 * max(1.0, abs(x)):
                moved.append({n: 0.0 for n in names})
                continue
            at = _estimates(fit_at({**values, name: end}), names)
            fits += 1
            moved.append({n: at[n] - centre[n] for n in names})
        spread[name] = {n: math.copysign(max(abs(moved[0][n]), abs(moved[1][n])), moved[1][n] - moved[0][n])
                        for n in names}
    return SearchSpread(spread, fits)


def _correlation(corr: ParameterCorrelation | None, std: Mapping[str, float], new_std: Mapping[str, float],
                 spread: SearchSpread) -> ParameterCorrelation | None:
    if corr is None or not spread.spread:
        return corr
    names = corr.names
    d = np.array([std.get(n, 0.0) if math.isfinite(std.get(n, math.inf)) else 0.0 for n in names])
    cov = np.asarray(corr.matrix, dtype=float) * np.outer(d, d)
    for per in spread.spread.values():
        v = np.array([per.get(n, 0.0) for n in names])
        cov += np.outer(v, v)
    s = np.array([new_std.get(n, 0.0) if math.isfinite(new_std.get(n, math.inf)) else 0.0 for n in names])
    with np.errstate(invalid="ignore", divide="ignore"):
        r = cov / np.outer(s, s)
    r[~np.isfinite(r)] = 0.0
    np.fill_diagonal(r, 1.0)
    return ParameterCorrelation(names, tuple(tuple(row) for row in r.round(6).tolist()))


def _too_wide(ident: Any, std: Mapping[str, float], extra_std: Mapping[str, float], gained: Mapping[str, float]
              ) -> list[Dependency]:
    """The parameters the spread made too uncertain (see the module docstring); not those already so."""
    limit = ident.settings.fit.max_relative_std
    half = math.hypot(ident.geometry.l, ident.geometry.b) / 2
    out = []
    for n in gained:
        extra = n in extra_std
        new, old = (extra_std[n], ident.extra_std[n]) if extra else (std[n], ident.std[n])
        if n in CENTRE_NAMES:
            scale, bound, label = half, half, f"the platform's half-diagonal ({half:.3g} m)"
        else:
            scale = abs(ident.extra[n] if extra else getattr(ident.parameters, n))
            bound, label = limit * scale, "its value"
        if new > bound and not old > bound:
            out.append(Dependency(n, (), math.nan, relative_std=new / scale if scale > 0 else math.inf, scale=label))
    return out


def with_spread(ident: Any, spread: SearchSpread) -> Any:
    """``ident`` with the searched values' spread in its std (``std``, ``extra_std``, the correlation;
    ``search_std``: what each parameter gained). Raises :class:`UnidentifiableError` for parameters the
    spread puts above the fit's limits (a warning with ``unexcited="report"``)."""
    gained = {n: v for n, v in spread.std().items() if v > 0}
    if not gained:
        return ident
    std = {n: math.hypot(s, gained[n]) if n in gained else s for n, s in ident.std.items()}
    extra_std = {n: math.hypot(s, gained[n]) if n in gained else s for n, s in ident.extra_std.items()}
    wide = _too_wide(ident, std, extra_std, gained)
    searched = ", ".join(sorted(spread.spread))
    if wide and not ident.settings.fit.reports_unexcited:
        raise UnidentifiableError(wide, f"with the uncertainty of the searched {searched} included (the estimates move "
                                        "with it; a narrower search range or data that fix it help): ")
    warnings = tuple(f"weakly excited with the searched {searched}: {d.describe()}" for d in wide)
    return dataclasses.replace(ident, std=std, extra_std=extra_std, search_std=gained,
                               correlation=_correlation(ident.correlation, ident.std, std, spread),
                               warnings=ident.warnings + warnings)
