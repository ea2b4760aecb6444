"""One-dimensional profiles of an objective (the concentrated likelihood of :mod:`.model_search`):
the minimum on a grid and by Brent's bounded search, the interval where the profile rises by a
threshold (ends by linear interpolation of ``sqrt(J - J_min)``, exact for a parabola, refined by
evaluations), and whether the optimum sits on a bound of the range.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["Profile", "profile_minimum", "profile_interval", "profile_std", "MAX_BRENT_EVALUATIONS"]

#: Brent's most evaluations per search.
MAX_BRENT_EVALUATIONS = 16


@dataclass(frozen=True)
class Profile:
    """The evaluations of J along one value: ``x`` (sorted, in the value's unit) and ``j``; the search
    ``bounds``; ``log_scale`` (the search's variable is ``log x``); ``xatol`` Brent's tolerance and
    ``step`` the grid step (in the search variable); ``fits`` evaluations made."""

    name: str
    x: np.ndarray
    j: np.ndarray
    bounds: tuple[float, float]
    log_scale: bool = False
    xatol: float = 0.0
    step: float = 0.0
    fits: int = 0

    @property
    def best(self) -> float:
        return float(self.x[int(np.argmin(self.j))])

    @property
    def j_min(self) -> float:
        return float(np.min(self.j))

    def z(self, x: np.ndarray | float) -> np.ndarray:
        """The search variable of values ``x``: ``log x`` on a log scale."""
        return np.log(x) if self.log_scale else np.asarray(x, dtype=float)

    def on_bound(self) -> float | None:
        """The bound of the range the optimum sits on (within twice Brent's tolerance), else None."""
        z = float(self.z(self.best))
        for bound in self.bounds:
            if abs(z - float(self.z(bound))) <= 2 * self.xatol + 1e-12 * max(1.0, abs(z)):
                return bound
        return None

    def with_points(self, x: np.ndarray, j: np.ndarray) -> "Profile":
        xs, js = np.concatenate([self.x, x]), np.concatenate([self.j, j])
        xs, first = np.unique(xs, return_index=True)
        return Profile(self.name, xs, js[first], self.bounds, self.log_scale, self.xatol, self.step, self.fits + len(x))


class _Evaluations:
    """J of values of the search variable, each evaluated once (cached); counts the evaluations."""

    def __init__(self, objective: Callable[[float], float], log_scale: bool) -> None:
        self.objective, self.log_scale, self.done = objective, log_scale, {}

    def __call__(self, z: float) -> float:
        z = float(z)
        if z not in self.done:
            value = float(self.objective(math.exp(z) if self.log_scale else z))
            if not math.isfinite(value):
                raise ValueError(f"the objective is {value!r} at {math.exp(z) if self.log_scale else z!r}: "
                                 "expected a finite number")
            self.done[z] = value
        return self.done[z]

    def profile(self, name: str, bounds: tuple[float, float], xatol: float, step: float) -> Profile:
        z = np.array(sorted(self.done))
        x = np.exp(z) if self.log_scale else z
        if self.log_scale:  # the bounds exactly, not exp(log(bound))
            x = np.where(np.isclose(x, bounds[0], rtol=1e-12), bounds[0], x)
            x = np.where(np.isclose(x, bounds[1], rtol=1e-12), bounds[1], x)
        return Profile(name, x, np.array([self.done[k] for k in z]), bounds, self.log_scale, xatol, step, len(z))


def profile_minimum(objective: Callable[[float], float], bounds: tuple[float, float], *, step: float,
                    xatol: float, log_scale: bool = False, start: float | None = None, name: str = "x",
                    max_evaluations: int = MAX_BRENT_EVALUATIONS) -> Profile:
    """The minimum of ``objective`` over ``bounds``: a grid of ``step`` (in the search variable:
    ``log x`` when ``log_scale``) and Brent's bounded search between the best grid point's
    neighbours; with ``start``, no grid: Brent's search within one ``step`` of it. ``xatol``:
    Brent's tolerance in the search variable. Returns the :class:`Profile` of all evaluations."""
    from scipy.optimize import minimize_scalar  # only when a model searches (identify's start-up stays light)

    lo, hi = float(bounds[0]), float(bounds[1])
    if not lo < hi or (log_scale and lo <= 0) or not (step > 0 and xatol > 0):
        raise ValueError(f"{name}: search range {bounds!r}, step {step!r}, xatol {xatol!r}: expected "
                         f"{'0 < ' if log_scale else ''}low < high and a step and tolerance > 0")
    ev = _Evaluations(objective, log_scale)
    zlo, zhi = (math.log(lo), math.log(hi)) if log_scale else (lo, hi)
    if start is None:
        grid = np.linspace(zlo, zhi, max(3, int(math.ceil((zhi - zlo) / step - 1e-9)) + 1))
        values = [ev(z) for z in grid]
        k = int(np.argmin(values))
        bracket = (grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)])
    else:
        z0 = min(max(math.log(start) if log_scale else float(start), zlo), zhi)
        ev(z0)
        bracket = (max(zlo, z0 - step), min(zhi, z0 + step))
    if bracket[1] - bracket[0] > 2 * xatol:
        minimize_scalar(ev, bounds=bracket, method="bounded",
                        options={"xatol": xatol, "maxiter": max_evaluations})
    return ev.profile(name, (lo, hi), xatol, step)


def _crossing(z: np.ndarray, rise: np.ndarray, best: int, level: float, side: int) -> float:
    """Where ``rise`` (J - J_min at the sorted points z) first reaches ``level`` going from ``best``
    to the ``side`` (-1 left, +1 right): linear in ``sqrt(rise)``; +-inf when it does not."""
    k = best
    while 0 <= k + side < z.size:
        nxt = k + side
        if rise[nxt] >= level:
            a, b = math.sqrt(max(rise[k], 0.0)), math.sqrt(rise[nxt])
            frac = (math.sqrt(level) - a) / (b - a) if b > a else 1.0
            return float(z[k] + frac * (z[nxt] - z[k]))
        k = nxt
    return side * math.inf


def _ends(profile: Profile, threshold: float) -> list[float]:
    z, j = profile.z(profile.x), profile.j
    best = int(np.argmin(j))
    return [_crossing(z, j - j[best], best, threshold, side) for side in (-1, 1)]


def _extended(profile: Profile, threshold: float, objective: Callable[[float], float], max_steps: int) -> Profile:
    """The profile with points added outwards (steps of ``profile.step``, doubling) on each side
    where it does not yet rise by ``threshold``, until it does or the bound is evaluated."""
    for k, side in enumerate((-1, 1)):
        for n in range(max_steps):
            if math.isfinite(_ends(profile, threshold)[k]):
                break
            z = profile.z(profile.x)
            bound = float(profile.z(profile.bounds[k]))
            outer = float(z.min() if side < 0 else z.max())
            if abs(outer - bound) <= 1e-12 * max(1.0, abs(bound)):
                break
            nxt = outer + side * profile.step * 2**n
            nxt = max(nxt, bound) if side < 0 else min(nxt, bound)
            x = profile.bounds[k] if nxt == bound else (math.exp(nxt) if profile.log_scale else nxt)
            profile = profile.with_points(np.array([x]), np.array([float(objective(x))]))
    return profile


def profile_interval(profile: Profile, threshold: float, objective: Callable[[float], float] | None = None,
                     refine: int = 1, max_steps: int = 8) -> tuple[tuple[float, float], Profile]:
    """The interval ``{x : J(x) <= J_min + threshold}`` of a profile (see the module docstring).
    With ``objective``: a side that does not rise by ``threshold`` among the points is extended
    outwards (at most ``max_steps`` evaluations), and each end refined by ``refine`` evaluations. An
    end where the profile does not rise by ``threshold`` within the range is -inf / +inf. Returns the
    interval (in the value's unit) and the profile with the evaluations added."""
    if not (threshold > 0 and math.isfinite(threshold)):
        raise ValueError(f"{profile.name}: interval threshold {threshold!r}: expected a finite number > 0")
    if objective is not None:
        profile = _extended(profile, threshold, objective, max_steps)
        for _ in range(refine):
            z = profile.z(profile.x)
            new = [e for e in _ends(profile, threshold)
                   if math.isfinite(e) and not np.any(np.isclose(z, e, rtol=0, atol=1e-12))]
            if not new:
                break
            x_new = np.exp(new) if profile.log_scale else np.array(new)
            profile = profile.with_points(x_new, np.array([float(objective(float(v))) for v in x_new]))
    lo, hi = (math.exp(e) if profile.log_scale and math.isfinite(e) else e for e in _ends(profile, threshold))
    return (lo, hi), profile


def profile_std(interval: tuple[float, float]) -> float:
    """Half the width of an interval; ``inf`` when an end is unbounded."""
    lo, hi = interval
    return (hi - lo) / 2 if math.isfinite(lo) and math.isfinite(hi) else math.inf
