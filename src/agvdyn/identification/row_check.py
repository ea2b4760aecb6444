"""Do the steering parameters depend on the rows? A check of a finished fit against the stick-slip rows.

Where the passive steering's joints stick harder than they slide (breakaway friction), the default rows
bias the steering parameters: each breakaway is a step the filter spreads past the steering guard
(docs/identification.md, "Breakaway friction"; at 1.3x on our plant d_vr -18 %, C_r +5 %, with stds of
5 % and 2 %: a silent wrong number). The rows that remove it, ``filtering="matched"`` with
``steering_guard=12`` (:data:`STICK_SLIP_ROWS`), cost a fifth of the rows and on effect-free logs agree
with the default ones within their stds. :func:`steering_row_check` refits with them and warns when a
steering parameter moves by more than :data:`THRESHOLD` times ``hypot`` of the two fits' stds (both fits
use the same data, so this understates the move's significance: a conservative test).

Measured (identification sequence, z = the largest of the six steering parameters'): effect-free 0.5-1.9
on 16 logs (11 of our plant, 5 MuJoCo); breakaway 1.2x / 0.02 rad/s 1.6-2.6 (5 logs), 1.3x / 0.05
2.9-3.8 (4), 1.5x / 0.1 4.8 (2).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

from agvdyn.identification.plausibility import ImplausibleError
from agvdyn.identification.regression import UnidentifiableError
from agvdyn.identification.settings import Filtering, IdentificationSettings

__all__ = ["STEERING_PARAMETERS", "STICK_SLIP_ROWS", "THRESHOLD", "steering_row_check", "row_check_applies",
           "with_row_check"]

STEERING_PARAMETERS = ("C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr")
#: The rows that keep the steering's stick phases out (docs/identification.md, "Breakaway friction").
STICK_SLIP_ROWS = {"filtering": "matched", "steering_guard": 12.0}
#: Moves beyond this many combined stds are reported (effect-free logs: at most 1.9 measured).
THRESHOLD = 2.5


def row_check_applies(ident: Any, settings: IdentificationSettings) -> bool:
    """The fit has rows the stick-slip rows would change (parallel filtering, a shorter steering guard)
    and estimates a steering parameter."""
    rows = settings.rows
    return (rows.filtering is Filtering.PARALLEL and rows.steering_guard < STICK_SLIP_ROWS["steering_guard"]
            and any(math.isfinite(ident.std.get(n, math.inf)) for n in STEERING_PARAMETERS))


def steering_row_check(ident: Any, refit: Callable[[IdentificationSettings], Any]) -> list[str]:
    """Warnings where the steering parameters of ``ident`` move beyond :data:`THRESHOLD` combined stds when
    fitted on the stick-slip rows: ``refit(settings)`` is the same fit with other settings (undetermined
    parameters reported, not refused; an impossible value refuses it: then nothing is said). Empty when
    :func:`row_check_applies` is false."""
    settings = ident.settings
    if not row_check_applies(ident, settings):
        return []
    try:  # the steering parameters compared; others the stick-slip rows leave undetermined are not refused
        other = refit(settings.replace(**STICK_SLIP_ROWS, unexcited="report", max_relative_std=math.inf))
    except (UnidentifiableError, ImplausibleError):
        return []
    moves = _moves(ident, other)
    if not moves or max(z for *_, z in moves) <= THRESHOLD:
        return []
    moved = "; ".join(f"{n} {b:.4g} +- {sb:.2g} against {a:.4g} +- {sa:.2g} ({z:.1f} std apart)"
                      for n, a, sa, b, sb, z in sorted(moves, key=lambda m: -m[-1]) if z > THRESHOLD)
    return [f"the steering parameters depend on the rows: with the stick-slip rows (filtering matched, steering "
            f"guard 12) {moved}. The steering joints likely stick harder than they slide (breakaway friction), "
            "which biases the default rows' C_l, C_r, d_vl, d_vr: refit with --filtering matched --steering-guard 12 "
            "(docs/identification.md, \"Breakaway friction\")"]


def _moves(a: Any, b: Any) -> list[tuple[str, float, float, float, float, float]]:
    """``(name, value, std, other value, other std, z)`` of the steering parameters both fits determine."""
    out = []
    for n in STEERING_PARAMETERS:
        sa, sb = a.std.get(n, math.inf), b.std.get(n, math.inf)
        if math.isfinite(sa) and math.isfinite(sb) and sa > 0 and sb > 0:
            va, vb = getattr(a.parameters, n), getattr(b.parameters, n)
            out.append((n, va, sa, vb, sb, abs(va - vb) / math.hypot(sa, sb)))
    return out


def with_row_check(ident: Any, refit: Callable[[IdentificationSettings], Any]) -> Any:
    """``ident`` with :func:`steering_row_check`'s warnings added."""
    said = steering_row_check(ident, refit)
    return dataclasses.replace(ident, warnings=ident.warnings + tuple(said)) if said else ident
