"""The model beyond the paper (issue 30): which extensions a model has, and their parameters.

The paper's model (eq. 14-19) has viscous + tanh-Coulomb friction, torques simultaneous with the
angles and the chassis centre of mass at the reference point. Three extensions, each optional:

* ``friction: stribeck`` -- per joint group g in (l: left steering, r: right steering, w: wheels)
  the friction torque of a joint rate ``w`` is (:func:`joint_friction`)

      d_v w + [d_c + (d_s - d_c) exp(-(w / w_s)^2)] tanh(w / epsilon)

  ``d_s`` (``d_sl``, ``d_sr``, ``d_sw``, N m) is the static (breakaway) level, ``d_c`` the sliding
  Coulomb level of the paper and ``w_s`` (``w_sl``, ``w_sr``, ``w_sw``, rad/s) the Stribeck
  velocity. Linear in ``d_v, d_c, d_s`` (regressor columns ``w``, ``(1 - e) tanh``, ``e tanh``
  with ``e = exp(-(w/w_s)^2)``); ``w_s`` enters nonlinearly and is found by a 1-D search.
  ``d_s = d_c`` is the paper's law.
* ``delay`` -- the torque columns lag the angles by ``delay_s`` seconds: the torque logged at t
  acted at ``t - delay_s`` (the identification uses ``u(t + delay_s)``, interpolated), on top of
  the sample-and-hold ``torque_lead``. ``"auto"``: found by a 1-D search on the regression residual.
* ``com_offset`` -- the chassis centre of mass at ``(x_c, y_c)`` m in the chassis frame. With
  ``a_x = x_ddot - y_dot gamma_dot``, ``a_y = y_ddot + x_dot gamma_dot`` (eq. 16), ``w = gamma_dot``
  and ``m = m_ch`` the chassis rows of Theta p become (Newton-Euler about the reference point)

      f_x = m a_x - m x_c w^2 - m y_c w_dot
      f_y = m a_y + m x_c w_dot - m y_c w^2
      f_g = (C_ch + C_l + C_r) w_dot + m x_c a_y - m y_c a_x

  with ``C_ch`` the chassis yaw inertia about the reference point (as :mod:`agvdyn.simulation.payload`
  reports it). Linear in ``(m_ch, C_ch, m_ch x_c, m_ch y_c)``; ``x_c, y_c`` follow by division.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from agvdyn.platform import EPSILON, Parameters

__all__ = ["FRICTION_LAWS", "FRICTION_GROUPS", "BREAKAWAY_NAMES", "STRIBECK_NAMES", "CENTRE_NAMES",
           "EXTRA_NAMES", "EXTRA_UNITS", "ModelSpec", "ModelParameters", "PAPER_MODEL", "joint_friction",
           "breakaway_weight", "model_from_mapping"]

FRICTION_LAWS = ("paper", "stribeck")
#: Joint groups of the friction terms: left steering, right steering, wheels; their paper names.
FRICTION_GROUPS = {"l": ("d_vl", "d_cl"), "r": ("d_vr", "d_cr"), "w": ("d_vw", "d_cw")}
BREAKAWAY_NAMES = ("d_sl", "d_sr", "d_sw")
STRIBECK_NAMES = ("w_sl", "w_sr", "w_sw")
CENTRE_NAMES = ("x_c", "y_c")
EXTRA_NAMES = BREAKAWAY_NAMES + STRIBECK_NAMES + CENTRE_NAMES
EXTRA_UNITS = {**{n: "N m" for n in BREAKAWAY_NAMES}, **{n: "rad/s" for n in STRIBECK_NAMES},
               **{n: "m" for n in CENTRE_NAMES}}
#: Default search ranges: Stribeck velocity (rad/s) and torque delay (s).
STRIBECK_RANGE = (0.005, 0.5)
DELAY_RANGE = (0.0, 0.02)

Delay = Union[float, str]


def _finite(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not math.isfinite(value):
        raise ValueError(f"model: {key}={value!r}: expected a finite number")
    return float(value)


def _range(key: str, value: Any, positive: bool) -> tuple[float, float]:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ValueError(f"model: {key}={value!r}: expected two numbers (low, high)")
    lo, hi = (_finite(key, v) for v in value)
    if not lo < hi or (positive and lo <= 0):
        raise ValueError(f"model: {key}={value!r}: expected {'0 < ' if positive else ''}low < high")
    return lo, hi


@dataclass(frozen=True)
class ModelSpec:
    """Which extensions the model has (the ``model:`` block of a platform or parameter file).

    ``friction``: ``"paper"`` or ``"stribeck"``; ``stribeck_velocities``: ``(w_sl, w_sr, w_sw)``
    rad/s when known, None to search them in ``stribeck_range``. ``delay``: seconds the torque
    columns lag the angles, or ``"auto"`` (searched in ``delay_range``). ``com_offset``: estimate
    the chassis centre of mass ``(x_c, y_c)``. ``held``: breakaway levels (some of ``d_sl, d_sr, d_sw``)
    held at the paper's law ``d_s = d_c``, not estimated and reported with an unbounded interval (their
    Stribeck velocities are not searched): set by a file, or by the fit where the data do not determine them.
    """

    friction: str = "paper"
    delay: Delay = 0.0
    com_offset: bool = False
    stribeck_velocities: tuple[float, float, float] | None = None
    stribeck_range: tuple[float, float] = STRIBECK_RANGE
    delay_range: tuple[float, float] = DELAY_RANGE
    held: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        friction = str(self.friction).strip().lower()
        if friction not in FRICTION_LAWS:
            raise ValueError(f"model: friction={self.friction!r}: expected one of {list(FRICTION_LAWS)}")
        object.__setattr__(self, "friction", friction)
        if isinstance(self.delay, str):
            if self.delay.strip().lower() != "auto":
                raise ValueError(f"model: delay={self.delay!r}: expected a number of seconds or 'auto'")
            object.__setattr__(self, "delay", "auto")
        else:
            object.__setattr__(self, "delay", _finite("delay", self.delay))
        if not isinstance(self.com_offset, (bool, np.bool_)):
            raise ValueError(f"model: com_offset={self.com_offset!r}: expected true or false")
        object.__setattr__(self, "com_offset", bool(self.com_offset))
        if self.stribeck_velocities is not None:
            v = self.stribeck_velocities
            if not isinstance(v, (tuple, list)) or len(v) != 3:
                raise ValueError(f"model: stribeck_velocities={v!r}: expected (w_sl, w_sr, w_sw) in rad/s")
            v = tuple(_finite(n, x) for n, x in zip(STRIBECK_NAMES, v))
            bad = [f"{n}={x!r}" for n, x in zip(STRIBECK_NAMES, v) if x <= 0]
            if bad:
                raise ValueError(f"model: {', '.join(bad)}: expected a Stribeck velocity > 0 rad/s")
            object.__setattr__(self, "stribeck_velocities", v)
        object.__setattr__(self, "stribeck_range", _range("stribeck_range", self.stribeck_range, True))
        object.__setattr__(self, "delay_range", _range("delay_range", self.delay_range, False))
        held = self.held
        bad = [held] if not isinstance(held, (tuple, list)) else [n for n in held if n not in BREAKAWAY_NAMES]
        if bad:
            raise ValueError(f"model: held: {', '.join(map(repr, bad))}: expected a list of some of "
                             f"{list(BREAKAWAY_NAMES)}")
        if held and not self.stribeck:
            raise ValueError(f"model: held={list(held)}: breakaway levels are held only with friction: stribeck")
        object.__setattr__(self, "held", tuple(n for n in BREAKAWAY_NAMES if n in held))

    @property
    def stribeck(self) -> bool:
        return self.friction == "stribeck"

    @property
    def free_stribeck_names(self) -> tuple[str, ...]:
        """The Stribeck velocities of the groups whose breakaway level is estimated (not ``held``)."""
        return tuple(w for w, d in zip(STRIBECK_NAMES, BREAKAWAY_NAMES) if self.stribeck and d not in self.held)

    @property
    def is_paper(self) -> bool:
        """No extension: the paper's model (a fixed delay of 0)."""
        return not self.stribeck and self.delay == 0.0 and not self.com_offset

    @property
    def resolved(self) -> bool:
        """Every nonlinear value known (no search left): what one regression can fit."""
        return self.delay != "auto" and (not self.stribeck or self.stribeck_velocities is not None)

    @property
    def extensions(self) -> tuple[str, ...]:
        """``("stribeck", "delay", "com_offset")``, those the model has."""
        return tuple(name for name, on in (("stribeck", self.stribeck), ("delay", self.delay != 0.0),
                                           ("com_offset", self.com_offset)) if on)

    @property
    def label(self) -> str:
        return "+".join(self.extensions) or "paper"

    @property
    def linear_names(self) -> tuple[str, ...]:
        """Names of the regression columns the extensions add, in order: the breakaway levels,
        then ``m_ch x_c, m_ch y_c`` (reported as ``x_c, y_c``)."""
        return (BREAKAWAY_NAMES if self.stribeck else ()) + (CENTRE_NAMES if self.com_offset else ())

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"friction": self.friction, "delay": self.delay, "com_offset": self.com_offset}
        if self.stribeck_velocities is not None:
            out["stribeck_velocities"] = list(self.stribeck_velocities)
        if self.stribeck_range != STRIBECK_RANGE:
            out["stribeck_range"] = list(self.stribeck_range)
        if self.delay_range != DELAY_RANGE:
            out["delay_range"] = list(self.delay_range)
        if self.held:
            out["held"] = list(self.held)
        return out

    def replace(self, **changes: Any) -> "ModelSpec":
        return ModelSpec(**{**self.__dict__, **changes})


PAPER_MODEL = ModelSpec()


def model_from_mapping(data: Any, where: str = "model") -> ModelSpec:
    """A :class:`ModelSpec` from the ``model:`` block of a file (``{friction, delay, com_offset, ...}``);
    errors name ``where`` and the offending key."""
    if data is None:
        return PAPER_MODEL
    if not isinstance(data, Mapping):
        raise ValueError(f"{where}: expected a mapping with friction, delay, com_offset, found {data!r}")
    known = {"friction", "delay", "com_offset", "stribeck_velocities", "stribeck_range", "delay_range", "held"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{where}: unknown keys {unknown}: expected some of {sorted(known)}")
    values = {k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items()}
    try:
        return ModelSpec(**values)
    except ValueError as exc:
        raise ValueError(f"{where}: {str(exc).removeprefix('model: ')}") from None


@dataclass(frozen=True)
class ModelParameters:
    """Values of a (possibly extended) model: the paper's 11 parameters, the extensions' named extra
    parameters (some of :data:`EXTRA_NAMES`), the torque delay (s) and the spec they belong to.
    ``ModelParameters(params)`` is the paper's model."""

    parameters: Parameters
    extra: Mapping[str, float] = field(default_factory=dict)
    delay_s: float = 0.0
    spec: ModelSpec = PAPER_MODEL

    def __post_init__(self) -> None:
        extra = {}
        for name, value in dict(self.extra).items():
            if name not in EXTRA_NAMES:
                raise ValueError(f"unknown extra parameter {name!r}: expected one of {list(EXTRA_NAMES)}")
            extra[name] = _finite(name, value)
        needed = (BREAKAWAY_NAMES + STRIBECK_NAMES if self.spec.stribeck else ()) + \
                 (CENTRE_NAMES if self.spec.com_offset else ())
        missing = [n for n in needed if n not in extra]
        if missing:
            raise ValueError(f"model {self.spec.label}: missing parameters {missing}")
        bad = [f"{n}={extra[n]!r}" for n in STRIBECK_NAMES if n in extra and extra[n] <= 0]
        if bad:
            raise ValueError(f"{', '.join(bad)}: expected a Stribeck velocity > 0 rad/s")
        object.__setattr__(self, "extra", extra)
        object.__setattr__(self, "delay_s", _finite("delay_s", self.delay_s))

    def value(self, name: str) -> float:
        """A paper parameter or an extra one; the paper's law where the extension is off
        (``d_s = d_c``, ``x_c = y_c = 0``; ``w_s`` is then irrelevant: 1.0)."""
        if name in self.extra:
            return self.extra[name]
        if name in BREAKAWAY_NAMES:
            return getattr(self.parameters, FRICTION_GROUPS[name[-1]][1])
        if name in STRIBECK_NAMES:
            return 1.0
        if name in CENTRE_NAMES:
            return 0.0
        return getattr(self.parameters, name)

    def friction(self, group: str) -> tuple[float, float, float, float]:
        """``(d_v, d_c, d_s, w_s)`` of a joint group ``"l"``, ``"r"`` or ``"w"``."""
        d_v, d_c = FRICTION_GROUPS[group]
        return (getattr(self.parameters, d_v), getattr(self.parameters, d_c), self.value(f"d_s{group}"),
                self.value(f"w_s{group}"))


def breakaway_weight(w: np.ndarray, w_s: float) -> np.ndarray:
    """``exp(-(w / w_s)^2)``: the share of the breakaway level at joint rate ``w``."""
    return np.exp(-np.square(np.asarray(w, dtype=float) / w_s))


def joint_friction(w, d_v: float, d_c: float, d_s: float | None = None, w_s: float | None = None,
                   epsilon: float = EPSILON) -> np.ndarray:
    """Friction torque ``d_v w + [d_c + (d_s - d_c) exp(-(w/w_s)^2)] tanh(w/epsilon)`` (the paper's
    ``d_v w + d_c tanh(w/epsilon)`` when ``d_s`` is None)."""
    w = np.asarray(w, dtype=float)
    level = d_c if d_s is None else d_c + (d_s - d_c) * breakaway_weight(w, w_s)
    return d_v * w + level * np.tanh(w / epsilon)
