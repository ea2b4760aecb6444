"""Physical plausibility of identified parameters, and the likely cause when they are not.

Masses and inertias must be positive and friction coefficients non-negative. An estimate that
breaks this is refused; the refusal tries the sign mistakes a logger or a mapping file makes
(one side's wheel torques or wheel angles with the wrong sign, all torques, a steering angle)
and names the one under which the same data give plausible parameters and a smaller residual.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.model_spec import BREAKAWAY_NAMES, EXTRA_UNITS
from agvdyn.platform import PARAMETER_UNITS

__all__ = ["POSITIVE", "NON_NEGATIVE", "SIGN_HYPOTHESES", "Implausible", "ImplausibleError", "SignConventionError",
           "implausible_parameters", "diagnose_signs", "encoder_sign_candidates", "pick_sign_candidate", "flipped"]

#: A fit of the same logs with the given columns negated (the caller streams them again).
Refit = Callable[[tuple[str, ...]], Any]

#: Encoder sign mistakes the rolling constraints reveal by themselves: (what, columns negated).
ENCODER_HYPOTHESES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("the right-hand wheel angles beta_fr, beta_rr have the wrong sign", ("beta_fr", "beta_rr")),
    ("the left-hand wheel angles beta_fl, beta_rl have the wrong sign", ("beta_fl", "beta_rl")),
    *((f"the wheel angle beta_{w} has the wrong sign", (f"beta_{w}",)) for w in ("fl", "rl", "fr", "rr")),
    ("the right steering angle alpha_r has the wrong sign", ("alpha_r",)),
    ("the left steering angle alpha_l has the wrong sign", ("alpha_l",)),
)

#: Parameters that must be > 0 (masses and inertias) and >= 0 (friction), eq. (18).
POSITIVE = ("C_l", "C_r", "m_ch", "C_ch", "B_w")
NON_NEGATIVE = ("d_vl", "d_cl", "d_vr", "d_cr", "d_vw", "d_cw")

#: Sign mistakes tried when an estimate is implausible: (what, log columns negated).
SIGN_HYPOTHESES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("the right-hand motor torques m_fr, m_rr have the wrong sign", ("m_fr", "m_rr")),
    ("the left-hand motor torques m_fl, m_rl have the wrong sign", ("m_fl", "m_rl")),
    ("all motor torques have the wrong sign", ("m_fl", "m_rl", "m_fr", "m_rr")),
    ("the right-hand wheel angles beta_fr, beta_rr have the wrong sign", ("beta_fr", "beta_rr")),
    ("the left-hand wheel angles beta_fl, beta_rl have the wrong sign", ("beta_fl", "beta_rl")),
    ("all wheel angles have the wrong sign", ("beta_fl", "beta_rl", "beta_fr", "beta_rr")),
    ("the steering angles alpha_l, alpha_r have the wrong sign", ("alpha_l", "alpha_r")),
)


@dataclass(frozen=True)
class Implausible:
    """A parameter estimate that is physically impossible."""

    name: str
    value: float
    std: float

    def describe(self) -> str:
        what = "mass or inertia" if self.name in POSITIVE else "friction coefficient"
        need = "> 0" if self.name in POSITIVE else ">= 0"
        std = f" +- {self.std:.3g}" if math.isfinite(self.std) else ""
        unit = PARAMETER_UNITS.get(self.name) or EXTRA_UNITS[self.name]
        return f"{self.name} = {self.value:.4g}{std} {unit} (a {what}, expected {need})"


class ImplausibleError(ValueError):
    """Physically impossible estimates; ``implausible`` lists them, ``cause`` the likely cause or None."""

    def __init__(self, implausible: Sequence[Implausible], cause: str | None, detail: str) -> None:
        self.implausible = tuple(implausible)
        self.cause = cause
        lines = "\n  ".join(i.describe() for i in self.implausible)
        super().__init__(f"physically impossible estimates:\n  {lines}\n{detail}")


def encoder_sign_candidates(logs: Iterable[Any], geometry: Any, settings: Any) -> list[tuple[str, tuple[str, ...], str]]:
    """Encoder sign mistakes that make the wheels roll (eq. 1) where, as given, they slip everywhere:
    (what, columns, detail) for each hypothesis that brings the median slip speed of the moving rows
    below a fifth and below the slip floor. Kinematics cannot tell negating the left wheels from
    negating the right ones (the vehicle then drives backwards): the torques decide, see
    :func:`pick_sign_candidate`. Uses the first continuous stretch of each log (``logs`` are read
    one at a time, until one reveals a candidate; of a long log its first piece)."""
    from agvdyn.identification.stretches import filtered_stretch, stretch_bounds

    def median_slip(log: Any) -> float:
        (a, b), *_ = stretch_bounds(log.t, log.alpha, log.beta, settings)[0]
        st = filtered_stretch(geometry, log, a, b, settings)
        moving = np.max(np.abs(st.beta_dot), axis=1) * geometry.r > 0.05
        return float(np.median(st.slip.max(axis=1)[moving])) if moving.sum() > 50 else math.nan

    out = []
    for log in logs:
        given = median_slip(log)
        if not given > settings.rows.slip_floor:
            continue
        for what, columns in ENCODER_HYPOTHESES:
            fixed = median_slip(flipped(log, columns))
            if fixed < 0.2 * given and fixed < settings.rows.slip_floor:
                out.append((what, columns, f"{getattr(log, 'path', None) or '<log>'}: the wheels slip by {given:.3g} m/s "
                                           f"(median of the moving rows) as the encoders are given, and roll "
                                           f"({fixed:.2g} m/s) with {', '.join(columns)} negated"))
        if out:
            break
    return out


def pick_sign_candidate(candidates: list[tuple[str, tuple[str, ...], str]], fit: Refit) -> SignConventionError | None:
    """The candidate under which the fit gives physically plausible parameters, as the error to
    raise; ``fit(columns) -> Identification`` of the logs with ``columns`` negated."""
    for what, columns, detail in candidates:
        try:
            ident = fit(columns)
        except ValueError:
            continue
        values = {n: getattr(ident.parameters, n) for n in (*POSITIVE, *NON_NEGATIVE) if n not in ident.fixed}
        if not implausible_parameters(values, ident.std)[0]:
            return SignConventionError(what, f"{detail}, and then give plausible parameters (m_ch = "
                                             f"{ident.parameters.m_ch:.5g} kg). Fix the sign in the logger, or give "
                                             "'sign: -1' for these signals in the mapping file (docs/io.md).")
    if candidates:
        what, columns, detail = candidates[0]
        return SignConventionError(what, f"{detail} (or the same on the other side together with all motor torques: "
                                         "the torques do not decide). Fix the sign in the logger, or give 'sign: -1' "
                                         "for these signals in the mapping file (docs/io.md).")
    return None


class SignConventionError(ImplausibleError):
    """The encoders contradict the rolling constraints unless one of them changes its sign
    (an :class:`ImplausibleError` with no estimate: the data are refused before the fit)."""

    def __init__(self, cause: str, detail: str) -> None:
        self.implausible = ()
        self.cause = cause
        ValueError.__init__(self, f"likely cause: {cause}. {detail}")


def implausible_parameters(values: dict[str, float], std: dict[str, float], *, significance: float = 3.0
                           ) -> tuple[list[Implausible], list[str]]:
    """(refused, warnings): masses/inertias <= 0 are refused; a negative friction (the breakaway levels
    ``d_s`` of :mod:`agvdyn.model_spec` too) is refused when it is below zero by more than
    ``significance`` std, else a warning (consistent with zero)."""
    refused, warnings = [], []
    for name, value in values.items():
        sd = std.get(name, math.nan)
        if name in POSITIVE and value <= 0:
            refused.append(Implausible(name, value, sd))
        elif (name in NON_NEGATIVE or name in BREAKAWAY_NAMES) and value < 0:
            if math.isfinite(sd) and -value <= significance * sd:
                unit = PARAMETER_UNITS.get(name) or EXTRA_UNITS[name]
                warnings.append(f"{name} = {value:.4g} {unit} is negative but within "
                                f"{significance:g} std ({sd:.3g}) of zero: the data hardly see this friction")
            else:
                refused.append(Implausible(name, value, sd))
    return refused, warnings


def flipped(log: Any, columns: tuple[str, ...]) -> Any:
    """The log with ``columns`` negated (a copy of its frame)."""
    frame = log.frame.copy()
    frame[list(columns)] = -frame[list(columns)]
    return dataclasses.replace(log, frame=frame)


def diagnose_signs(fit: Refit, residual: float) -> tuple[str | None, str]:
    """Try each sign hypothesis on the logs; ``fit(columns) -> (Identification, residual RMS over
    all rows)`` of the logs with ``columns`` negated (plausibility off).

    Returns (cause, message): among the hypotheses under which every estimate is physically
    plausible, the one with the smallest residual (RMS over all generalized torques; ``residual``
    is that of the data as given, for the message), or None. A sign mistake need not raise the
    residual much (a model with impossible parameters can fit wrong-sign data closely), so
    plausibility decides and the residual only ranks.
    """
    best: tuple[float, str, Any] | None = None
    for what, columns in SIGN_HYPOTHESES:
        try:
            ident, rms = fit(columns)
        except ValueError:
            continue
        values = {n: getattr(ident.parameters, n) for n in (*POSITIVE, *NON_NEGATIVE) if n not in ident.fixed}
        refused, _ = implausible_parameters(values, ident.std)
        if not refused and (best is None or rms < best[0]):
            best = (rms, what, ident)
    if best is None:
        return None, ("no single sign mistake explains it (tried: " + "; ".join(w for w, _ in SIGN_HYPOTHESES) +
                      "). Check the units and the side of the gear of torques and wheel angles (motor side, "
                      "i_G), the wheel order fl, rl, fr, rr, and whether the data excite the parameters.")
    rms, what, ident = best
    p = ident.parameters
    return what, (f"likely cause: {what}. With them negated the same data give m_ch = {p.m_ch:.5g} kg, "
                  f"C_ch = {p.C_ch:.5g} kg m^2, d_vw = {p.d_vw:.4g} N m s/rad, all physically plausible, with a "
                  f"residual RMS of {rms:.4g} N m (as given: {residual:.4g} N m). Fix the sign in the logger, or give 'sign: -1' for these "
                  "signals in the mapping file (docs/io.md).")
