"""Rolling constraints (eq. 1-2), the ICR relation (eq. 6-8) and the motion modes (eq. 9).

Conventions (PLATFORM.md): ``alpha`` is ``(N, 2)`` = ``(alpha_l, alpha_r)``, the headings of the
front wheels; the rear wheels are mirrored. ``q_dot`` is ``(N, 9)`` =
``(v_x, v_y, omega, alpha_l_dot, alpha_r_dot, beta_fl_dot, beta_rl_dot, beta_fr_dot, beta_rr_dot)``
with body-frame chassis velocities. Every function takes a leading sample axis.
"""
from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from agvdyn._jit import njit
from agvdyn.platform import Geometry

#: Tolerance (rad) on the steering angles of eq. (9) when a measured configuration is assigned
#: to a motion mode: about 1.1 degree, several times the steering-angle noise and the steady
#: tracking error of the steering loop, far below the distance between modes.
MODE_TOLERANCE = 0.02
#: Tolerance (rad) on values of alpha beyond the mechanical stops at +-pi/2 (encoder round-off).
STOP_TOLERANCE = 1e-6

_SIDE = np.array([0, 0, 1, 1])  # steering side of each wheel fl, rl, fr, rr (0 = left)
N_Q = 9


class Mode(IntEnum):
    """Motion modes of eq. (9); STRAIGHT is mode 2 with alpha_v = 0 (sec. 6)."""

    PARKING = 1
    CAR_LIKE = 2
    LATERAL = 3
    ROTATION = 4
    STRAIGHT = 5

    @property
    def label(self) -> str:
        return "2s" if self is Mode.STRAIGHT else str(int(self))

    @property
    def coordinates(self) -> tuple[str, ...]:
        """Names of the generalized velocities s_k_dot, eq. (10)-(13)."""
        return _COORDINATES[self]

    @property
    def dof(self) -> int:
        return len(_COORDINATES[self])

    @classmethod
    def from_label(cls, label: "str | int | Mode") -> "Mode":
        if isinstance(label, Mode):
            return label
        key = str(label).strip().lower()
        if key in _LABELS:
            return _LABELS[key]
        raise ValueError(f"unknown motion mode {label!r}: expected one of {sorted(_LABELS)}")


_COORDINATES = {
    Mode.PARKING: ("alpha_l", "alpha_r"),
    Mode.CAR_LIKE: ("alpha_v", "x_ch"),
    Mode.LATERAL: ("y_ch",),
    Mode.ROTATION: ("gamma_ch",),
    Mode.STRAIGHT: ("x_ch",),
}
_LABELS = {
    "1": Mode.PARKING, "parking": Mode.PARKING, "alignment": Mode.PARKING,
    "2": Mode.CAR_LIKE, "car": Mode.CAR_LIKE, "car-like": Mode.CAR_LIKE, "car_like": Mode.CAR_LIKE,
    "3": Mode.LATERAL, "lateral": Mode.LATERAL,
    "4": Mode.ROTATION, "rotation": Mode.ROTATION,
    "2s": Mode.STRAIGHT, "straight": Mode.STRAIGHT, "5": Mode.STRAIGHT,
}


def as_alpha(alpha, *, name: str = "alpha") -> np.ndarray:
    """Check steering angles ``(N, 2)`` (or ``(2,)``): finite and within the stops [-pi/2, pi/2]."""
    alpha = np.atleast_2d(np.asarray(alpha, dtype=float))
    if alpha.ndim != 2 or alpha.shape[1] != 2:
        raise ValueError(f"{name} of shape {alpha.shape}: expected (N, 2) = (alpha_l, alpha_r)")
    bad = ~np.isfinite(alpha)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(f"{name}[{row}, {('alpha_l', 'alpha_r')[col]}] = {alpha[row, col]}: expected a finite angle")
    out = np.abs(alpha) > math.pi / 2 + STOP_TOLERANCE
    if out.any():
        row, col = np.argwhere(out)[0]
        raise ValueError(
            f"{name}[{row}, {('alpha_l', 'alpha_r')[col]}] = {alpha[row, col]:.6g} rad: "
            f"expected within [-pi/2, pi/2] (mechanical stops)"
        )
    return alpha


def _rows(x, n: int, width: int, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim == 1 and width > 1 and x.shape[0] == width:
        x = x[None, :]
    if width == 1 and x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[1] != width or x.shape[0] not in (1, n):
        raise ValueError(f"{name} of shape {x.shape}: expected ({n}, {width})")
    if not np.isfinite(x).all():
        row = int(np.argwhere(~np.isfinite(x))[0, 0])
        raise ValueError(f"{name}[{row}] = {x[row]}: expected finite values")
    return np.broadcast_to(x, (n, width))


def wheel_headings(geom: Geometry, alpha: np.ndarray) -> np.ndarray:
    """Headings theta_i ``(N, 4)`` of the wheels fl, rl, fr, rr (rear wheels mirrored)."""
    return alpha[:, _SIDE] * geom.heading_sign


@njit(cache=True, inline="always")
def wheel_frame(i, l, b):  # pragma: no cover - compiled
    """Wheel i (fl, rl, fr, rr) of eq. (1)-(2): on the left, sigma (+1 front, -1 rear), side (+1
    left, -1 right) and its mounting point (cx, cy) in the chassis frame."""
    left = i < 2
    sigma = 1.0 if i % 2 == 0 else -1.0
    side = 1.0 if left else -1.0
    return left, sigma, side, (l / 2 if i % 2 == 0 else -l / 2), (b / 2 if left else -b / 2)


@njit(cache=True)
def constraint_matrix_into(l, b, a, radii, alpha_l, alpha_r, A):  # pragma: no cover - compiled
    """A(alpha) ``(8, 9)`` of eq. (1)-(2) for one configuration, written into ``A``.

    Row i (lateral) ``e_lat . (v + omega z x c_i)``; row 4+i (longitudinal)
    ``e_long . (v + omega z x c_i) - s_i a (omega + theta_i_dot) - r_i beta_i_dot`` with the
    rolling radii ``radii`` (4,) (all r for the model; a simulated vehicle's radius errors
    otherwise); the rows are the slip velocities of the contact points.
    """
    A[:, :] = 0.0
    for i in range(4):
        left, sigma, side, cx, cy = wheel_frame(i, l, b)
        theta = sigma * (alpha_l if left else alpha_r)
        c, s = np.cos(theta), np.sin(theta)
        A[i, 0], A[i, 1], A[i, 2] = -s, c, s * cy + c * cx
        A[4 + i, 0], A[4 + i, 1], A[4 + i, 2] = c, s, -c * cy + s * cx - side * a
        A[4 + i, 3 if left else 4] = -side * a * sigma
        A[4 + i, 5 + i] = -radii[i]


@njit(cache=True)
def _constraint_matrices(l, b, a, r, alpha):  # pragma: no cover - compiled
    A = np.empty((alpha.shape[0], 8, 9))
    radii = np.full(4, r)
    for j in range(alpha.shape[0]):
        constraint_matrix_into(l, b, a, radii, alpha[j, 0], alpha[j, 1], A[j])
    return A


def constraint_matrix(geom: Geometry, alpha) -> np.ndarray:
    """Constraint matrix A(alpha) ``(N, 8, 9)`` of eq. (1)-(2).

    Rows 0-3: lateral rolling constraints, rows 4-7: longitudinal ones, wheels fl, rl, fr, rr.
    """
    alpha = np.ascontiguousarray(as_alpha(alpha))
    return _constraint_matrices(geom.l, geom.b, geom.a, geom.r, alpha)


# --- ICR relation, eq. (6)-(8) ------------------------------------------------------------

def max_virtual_angle(geom: Geometry) -> float:
    """Largest |alpha_v| of the car-like mode: the outer wheel reaches its stop at arctan(l/b)."""
    return math.atan2(geom.l, geom.b)


def steering_from_virtual(geom: Geometry, alpha_v) -> np.ndarray:
    """Steering angles alpha = f_ICR(alpha_v) ``(N, 2)`` of eq. (8).

    From ``l/(2 tan alpha_l) + b/2 = l/(2 tan alpha_r) - b/2 = l/(2 tan alpha_v) = y_ICR``:
    ``alpha_l = atan2(sin alpha_v, cos alpha_v - (b/l) sin alpha_v)`` and the same with ``+ b/l`` for
    alpha_r. Example: ``alpha_v = 0.3`` on the prototype gives ``alpha = (0.3716, 0.2510)``.
    """
    av = _check_virtual(geom, alpha_v)
    k = geom.b / geom.l
    s, c = np.sin(av), np.cos(av)
    return np.stack([np.arctan2(s, c - k * s), np.arctan2(s, c + k * s)], axis=1)


def steering_from_virtual_derivatives(geom: Geometry, alpha_v) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives ``d alpha / d alpha_v`` and ``d2 alpha / d alpha_v2`` ``(N, 2)`` of eq. (8).

    With ``D = sin^2 + (cos -+ k sin)^2 = 1 -+ k sin(2 alpha_v) + k^2 sin^2 alpha_v``:
    ``d alpha / d alpha_v = 1 / D`` and ``d2 alpha / d alpha_v2 = -D' / D^2``.
    """
    av = _check_virtual(geom, alpha_v)
    k = np.array([geom.b / geom.l, -geom.b / geom.l])
    s2, c2, s = np.sin(2 * av)[:, None], np.cos(2 * av)[:, None], np.sin(av)[:, None]
    D = 1 - k * s2 + k**2 * s**2
    dD = -2 * k * c2 + k**2 * s2
    return 1 / D, -dD / D**2


def _check_virtual(geom: Geometry, alpha_v) -> np.ndarray:
    av = np.atleast_1d(np.asarray(alpha_v, dtype=float))
    if av.ndim != 1:
        raise ValueError(f"alpha_v of shape {av.shape}: expected (N,)")
    limit = max_virtual_angle(geom)
    bad = ~np.isfinite(av) | (np.abs(av) > limit + STOP_TOLERANCE)
    if bad.any():
        row = int(np.argmax(bad))
        raise ValueError(
            f"alpha_v[{row}] = {av[row]:.6g} rad: expected finite and within +-arctan(l/b) = +-{limit:.6g} "
            "(beyond it the outer wheel passes its stop at pi/2)"
        )
    return av


@njit(cache=True, nogil=True)
def icr_state_trig(k, sin_l, cos_l, sin_r, cos_r):  # pragma: no cover - compiled
    """:func:`icr_state` from the sines and cosines of the steering angles (computed once by callers
    that need them for the constraints too)."""
    av_l = np.arctan2(sin_l, cos_l + k * sin_l)
    av_r = np.arctan2(sin_r, cos_r - k * sin_r)
    return 0.5 * (av_l + av_r), (av_l - av_r + np.pi / 2) % np.pi - np.pi / 2


@njit(cache=True, nogil=True)
def icr_state(k, alpha_l, alpha_r):  # pragma: no cover - compiled
    """(alpha_v, residual) of one configuration, ``k = b/l``: inverse of eq. (8) per side, their
    mean, and the ICR residual of eq. (9) (difference of the two sides' values modulo pi)."""
    return icr_state_trig(k, np.sin(alpha_l), np.cos(alpha_l), np.sin(alpha_r), np.cos(alpha_r))


@njit(cache=True)
def _icr_states(k, alpha):  # pragma: no cover - compiled
    out = np.empty((alpha.shape[0], 2))
    for j in range(alpha.shape[0]):
        out[j, 0], out[j, 1] = icr_state(k, alpha[j, 0], alpha[j, 1])
    return out


def _icr(geom: Geometry, alpha) -> np.ndarray:
    return _icr_states(geom.b / geom.l, np.ascontiguousarray(as_alpha(alpha)))


def virtual_from_steering(geom: Geometry, alpha) -> np.ndarray:
    """Virtual steering angle alpha_v ``(N,)``: inverse of eq. (8), mean of both sides' values."""
    return _icr(geom, alpha)[:, 0]


def icr_residual(geom: Geometry, alpha) -> np.ndarray:
    """Residual of the ICR relation f_ICR,lr(alpha) = 0 of eq. (9) as an angle ``(N,)`` (rad).

    Difference of the virtual angles implied by the left and the right side, taken modulo pi
    (the axle lines are lines, not rays). Zero in modes 2 and 4.
    """
    return _icr(geom, alpha)[:, 1]


def nominal_steering(geom: Geometry, mode: Mode) -> np.ndarray | None:
    """Fixed steering angles ``(2,)`` of modes 3, 4 and straight (eq. 9); None for modes 1 and 2."""
    mode = Mode.from_label(mode)
    if mode is Mode.LATERAL:
        return np.array([-math.pi / 2, math.pi / 2])
    if mode is Mode.ROTATION:
        return geom.rotation_angle * np.array([-1.0, 1.0])
    if mode is Mode.STRAIGHT:
        return np.zeros(2)
    return None


def detect_mode(geom: Geometry, alpha, tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Motion mode of each configuration ``(N,)`` as Mode values, eq. (9).

    A row is in mode 3, 4 or straight when both angles are within ``tolerance`` of the mode's
    fixed angles, in mode 2 when |icr_residual| <= tolerance and |alpha_v| is within the stops,
    otherwise in mode 1 (checked in that order). Mode detection says which relation the steering
    angles satisfy; whether the chassis moves is a matter of the velocities.
    """
    alpha = as_alpha(alpha)
    if not tolerance > 0:
        raise ValueError(f"tolerance={tolerance!r}: expected > 0 rad")
    mode = np.full(alpha.shape[0], int(Mode.PARKING), dtype=np.int8)
    icr = _icr(geom, alpha)
    car = (np.abs(icr[:, 1]) <= tolerance) & (np.abs(icr[:, 0]) <= max_virtual_angle(geom) + tolerance)
    mode[car] = Mode.CAR_LIKE
    for m in (Mode.STRAIGHT, Mode.ROTATION, Mode.LATERAL):
        nominal = nominal_steering(geom, m)
        near = (np.abs(alpha[:, 0] - nominal[0]) <= tolerance) & (np.abs(alpha[:, 1] - nominal[1]) <= tolerance)
        mode[near] = m
    return mode


def check_mode(geom: Geometry, mode: Mode, alpha: np.ndarray, tolerance: float = MODE_TOLERANCE) -> None:
    """Raise ValueError naming the first configuration that is not in ``mode``."""
    mode = Mode.from_label(mode)
    if mode is Mode.PARKING:
        return
    nominal = nominal_steering(geom, mode)
    if nominal is not None:
        err = np.max(np.abs(alpha - nominal), axis=1)
        what = f"alpha = {tuple(np.round(nominal, 6))}"
    else:
        icr = _icr(geom, alpha)
        err = np.where(np.abs(icr[:, 0]) <= max_virtual_angle(geom) + tolerance, np.abs(icr[:, 1]), np.inf)
        what = "the ICR relation of eq. (6)-(8)"
    bad = err > tolerance
    if bad.any():
        row = int(np.argmax(bad))
        raise ValueError(
            f"alpha[{row}] = ({alpha[row, 0]:.6g}, {alpha[row, 1]:.6g}) rad is not in mode {mode.label} "
            f"({mode.name.lower()}): expected {what} within {tolerance} rad"
        )
