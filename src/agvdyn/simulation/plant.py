"""The "real vehicle": rigid-body dynamics with tyre slip instead of rolling constraints.

This is NOT the identification model. Nine generalized velocities (PLATFORM.md)
``v = (v_x, v_y, omega, alpha_l_dot, alpha_r_dot, beta_fl_dot, beta_rl_dot, beta_fr_dot, beta_rr_dot)``
(body-frame chassis velocities) and nine positions ``(X, Y, gamma, alpha_l, alpha_r, beta_*)``
(world pose). The eight rolling constraints ``A(alpha) v = 0`` of eq. (1)-(2) are replaced by
tyre forces on the slip velocities ``A(alpha) v`` (lateral and longitudinal slip of each contact
point): ``F = -mu F_z tanh(|sigma|) sigma / |sigma|`` with ``sigma = (C_lat s_lat, C_long s_long) /
(V mu F_z)``, where ``C_*`` are slip stiffnesses (N per unit slip) and ``V = max(|r beta_dot|,
|v_contact|, v_0)`` the rolling speed regularised at ``v_0`` (a linear damper near standstill).
Steering is passive: only the longitudinal tyre forces acting at the offset ``a`` turn it.
A slip scenario (slip.py) can lower ``mu`` per wheel where its contact point is on a floor patch.

Mass matrix: with the neglected effects off, ``M = diag(m_ch, m_ch, C_ch + C_l + C_r, C_l, C_r, B_w I_4)``
and the Coriolis terms of eq. (16), i.e. exactly the identification model's inertia. Switching
``steering_masses`` on places four steering units of mass ``unit_mass`` with their centre of mass
at ``unit_offset`` from the steering axis along the axle (where the wheel is); the chassis body
keeps the rest, so that total mass and yaw inertia at alpha = 0 still equal ``m_ch`` and
``C_ch + C_l + C_r``, but the inertia now depends on alpha and steering and chassis are coupled
(the gyroscopic/Coriolis terms the paper neglects, sec. 4). The spin angular momentum of the
wheels yawing with their units gives a torque about the horizontal wheel heading, taken by ground
and bearings: no component in the plane, not modelled.

Integration (why): the tyres make the system stiff (a wheel's reflected inertia ``B_w/r^2 = 12 kg``
against a slip damping of ``C/v_0 ~ 1e6 N s/m`` has a time constant of ~10 us). Tyre and
friction forces are linearised about the current state and one linearly-implicit Euler step
solves ``(M + dt D) v_{n+1} = M v_n + dt (B u - h(x_n, v_n) - e + f_stops)``, then
``x_{n+1} = x_n + dt v_{n+1}``: tyres with their secant ``F/s`` (linear below saturation),
viscous friction exactly, the Coulomb friction of a moving joint with its tangent
(Rosenbrock-Euler, exact for a constant sliding force) and of a joint that one step could stop
with its secant (never flips the sign of v, holds a stuck joint). The step is stable for any
stiffness, and as the slip stiffness grows it becomes the M-orthogonal projection onto
``A v = 0``, i.e. the rolling-constraint model: the convergence test measures it. The step is
``T_s / substeps`` (default 0.5 ms) for accuracy of the explicit Coriolis terms.

Coulomb friction with stiction: ``F = level v / v_stick`` for ``|v| <= v_stick = 1e-4 rad/s``,
``level sign(v)`` beyond, ``level = d_c (1 + (ratio - 1) exp(-(v / v_stribeck)^2))``, i.e. the
level ``d_c + (d_s - d_c) exp(-(v / w_s)^2)`` of :func:`agvdyn.model_spec.joint_friction` with
``d_s = ratio d_c`` and ``w_s = v_stribeck``, per joint group (left steering, right steering,
wheels: ``PlantSettings.breakaway_ratios`` / ``stribeck_velocities``, by default the global
``breakaway_ratio`` / ``stribeck_velocity`` for all three). Below the breakaway torque ``ratio d_c``
a joint sticks (creep below 1e-4 rad/s, a numerical regularisation 100 times narrower than the
model's tanh with epsilon = 0.01 rad/s, which creeps at up to 0.01 rad/s under any torque); above
it the joint slides with ``d_c sign(v)``.
A slow joint outside the stick band takes the tangent (the secant's ``level v_new / |v_old|`` held a
joint breaking away until 3-21 % above its level), and the secant again only where the tangent would
reverse it (``_plant_kernels._friction_terms``, ``_secant_where_reversed``).
``coulomb="tanh"`` uses the identification model's ``d_c tanh(v / epsilon)`` instead.

Payload (issue 31, payload.py): a load fixed to the chassis, mass ``m_p``, first moments
``S = m_p (x_p, y_p)`` and yaw inertia ``J_p`` about the reference point, adds to the chassis block
``M[0,0] = M[1,1] += m_p``, ``M[2,2] += J_p``, ``M[0,2] = M[2,0] -= S_y``, ``M[1,2] = M[2,1] += S_x``
(from its kinetic energy ``m_p/2 |v|^2 + J_p/2 omega^2 + omega (S_x v_y - S_y v_x)``) and to the
body-frame forces ``h += (-omega (m_p v_y + omega S_x), omega (m_p v_x - omega S_y),
omega (S_x v_x + S_y v_y))``: exact rigid-body terms (``v . h = 0``: they do no work). With an
offset the chassis' centre of mass leaves the reference point, and translation and yaw couple.
:func:`set_payload` writes them into the constants between samples (``simulate`` splits its chunks
at the events); without a payload the kernels skip the terms (logs bit-identical).

The compiled plant is in ``_plant_kernels.py``, the closed loop that drives it in ``_kernels.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from agvdyn.model_spec import FRICTION_GROUPS
from agvdyn.platform import EPSILON, Geometry, Parameters

GRAVITY = 9.81

from agvdyn.simulation._kernels import kinetic_energy, run_open_loop  # noqa: F401  (compiled, re-exported)
from agvdyn.simulation._plant_kernels import (  # noqa: F401  (compiled plant, re-exported)
    _A, _B, _BW, _CB, _CLAT, _CLONG, _COUL, _DCL, _DCR, _DSTOP, _DVL, _DVR, _DVW, _DCW, _EPS, _EU, _FZ, _IG,
    _JUL, _JUR, _KSTOP, _L, _MB, _MU, _MU_MASS, _NCONST, _R, _RATIO, _RW, _TLIM, _V0, _VSTICK, _VSTRIB,
    _PJ, _PM, _PSX, _PSY, _mass_matrix, plant_step,
)

_COULOMB = {"stiction": 0.0, "tanh": 1.0, "none": 2.0}
#: Joint groups of the breakaway friction, in the order of ``breakaway_ratios`` (model_spec.FRICTION_GROUPS).
BREAKAWAY_GROUPS = tuple(FRICTION_GROUPS)


@dataclass(frozen=True)
class PlantSettings:
    """Settings of the simulated vehicle beyond the 11 parameters of eq. (18).

    Tyres: ``slip_stiffness_long`` / ``slip_stiffness_lat`` (N per unit slip), friction coefficient
    ``mu``, standstill regularisation ``slip_velocity`` (m/s). Neglected effects, each switchable:
    ``coulomb`` friction model (``"stiction"`` true stick/slip, ``"tanh"`` the model's, ``"none"``),
    ``breakaway_ratio`` (static / sliding friction, Stribeck velocity ``stribeck_velocity``) for all
    joint groups, or per group ``breakaway_ratios`` / ``stribeck_velocities`` = (left steering, right
    steering, wheels) (None: the global value for all three; giving both is an error, see
    :meth:`group_breakaway`, :meth:`with_breakaway`),
    ``steering_masses`` (unit masses ``unit_mass`` at ``unit_offset`` from the steering axis; offset
    None = the offset a; mass None = 30 kg, or less where 30 kg at that offset would take more than
    half of C_l/2 or C_r/2 as the units' share of the steering inertia), ``torque_limit`` (motor peak torque in N m; None = unlimited),
    ``wheel_radius_error`` (relative error of each wheel's true rolling radius against the nominal
    ``r`` that controller, odometry and model use: tyre tolerance and load; the main source of
    odometry drift besides slip).
    Mechanical steering stops at +-pi/2: stiffness ``stop_stiffness``, damping ``stop_damping``.
    """

    slip_stiffness_long: float = 4.0e4
    slip_stiffness_lat: float = 3.0e4
    mu: float = 0.8
    slip_velocity: float = 0.02
    coulomb: Literal["stiction", "tanh", "none"] = "stiction"
    stick_velocity: float = 1e-4
    breakaway_ratio: float = 1.0
    stribeck_velocity: float = 0.01
    breakaway_ratios: tuple[float, float, float] | None = None
    stribeck_velocities: tuple[float, float, float] | None = None
    steering_masses: bool = True
    unit_mass: float | None = None
    unit_offset: float | None = None
    torque_limit: float | None = 6.0
    wheel_radius_error: tuple[float, float, float, float] = (0.002, -0.0015, 0.001, -0.002)
    stop_stiffness: float = 2.0e4
    stop_damping: float = 200.0
    substeps: int = 4

    def __post_init__(self) -> None:
        if self.coulomb not in _COULOMB:
            raise ValueError(f"coulomb={self.coulomb!r}: expected one of {sorted(_COULOMB)}")
        for key in ("slip_stiffness_long", "slip_stiffness_lat", "mu", "slip_velocity", "stick_velocity",
                    "stribeck_velocity", "stop_stiffness", "stop_damping"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"plant setting {key}={v!r}: expected a finite number > 0")
        if not self.breakaway_ratio >= 1:
            raise ValueError(f"breakaway_ratio={self.breakaway_ratio!r}: expected >= 1 (static >= sliding friction)")
        self._check_groups()
        if self.unit_mass is not None and not self.unit_mass >= 0:
            raise ValueError(f"unit_mass={self.unit_mass!r}: expected >= 0 kg")
        if self.torque_limit is not None and not self.torque_limit > 0:
            raise ValueError(f"torque_limit={self.torque_limit!r}: expected > 0 N m or None")
        if len(self.wheel_radius_error) != 4 or not all(abs(e) < 0.2 for e in self.wheel_radius_error):
            raise ValueError(f"wheel_radius_error={self.wheel_radius_error!r}: expected 4 relative errors, |e| < 0.2")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(f"substeps={self.substeps!r}: expected an integer >= 1")

    def _check_groups(self) -> None:
        """The per-group breakaway: 3 values each, ratios >= 1, Stribeck velocities > 0, and not
        together with a global value other than its default."""
        for key, one, expected in (("breakaway_ratios", "breakaway_ratio", ">= 1 (static >= sliding friction)"),
                                   ("stribeck_velocities", "stribeck_velocity", "> 0 rad/s")):
            values = getattr(self, key)
            if values is None:
                continue
            if not isinstance(values, (tuple, list)) or len(values) != 3:
                raise ValueError(f"plant setting {key}={values!r}: expected 3 numbers (left steering, right "
                                 "steering, wheels)")
            bad = [f"{g}={v!r}" for g, v in zip(BREAKAWAY_GROUPS, values)
                   if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                   or not (v >= 1 if key == "breakaway_ratios" else v > 0)]
            if bad:
                raise ValueError(f"plant setting {key}: {', '.join(bad)}: expected a finite number {expected}")
            if getattr(self, one) != PlantSettings.__dataclass_fields__[one].default:
                raise ValueError(f"plant settings {one}={getattr(self, one)!r} and {key}={values!r}: expected one "
                                 f"of them ({one} for all joint groups, {key} per group)")
            object.__setattr__(self, key, tuple(float(v) for v in values))

    def group_breakaway(self) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        """``((ratio, w_s), ...)`` of the joint groups left steering, right steering, wheels:
        breakaway ratio d_s / d_c and Stribeck velocity w_s (rad/s) of the friction law."""
        ratios = self.breakaway_ratios or (self.breakaway_ratio,) * 3
        speeds = self.stribeck_velocities or (self.stribeck_velocity,) * 3
        return tuple(zip(ratios, speeds))  # type: ignore[return-value]

    def with_breakaway(self, group: str, ratio: float, stribeck_velocity: float | None = None) -> "PlantSettings":
        """These settings with breakaway ``ratio`` (and Stribeck velocity, None: unchanged) in joint
        ``group`` ``"l"``, ``"r"``, ``"w"`` or ``"all"``, in the per-group form."""
        from dataclasses import replace

        if group not in (*BREAKAWAY_GROUPS, "all"):
            raise ValueError(f"breakaway group {group!r}: expected one of {[*BREAKAWAY_GROUPS, 'all']}")
        pairs = [list(p) for p in self.group_breakaway()]
        for g, pair in zip(BREAKAWAY_GROUPS, pairs):
            if group in (g, "all"):
                pair[0] = ratio
                pair[1] = pair[1] if stribeck_velocity is None else stribeck_velocity
        defaults = PlantSettings.__dataclass_fields__
        return replace(self, breakaway_ratio=defaults["breakaway_ratio"].default,
                       stribeck_velocity=defaults["stribeck_velocity"].default,
                       breakaway_ratios=tuple(p[0] for p in pairs), stribeck_velocities=tuple(p[1] for p in pairs))

    def ideal(self) -> "PlantSettings":
        """The same tyres with every neglected effect off (the identification model's structure)."""
        from dataclasses import replace
        return replace(self, coulomb="tanh", steering_masses=False, torque_limit=None, wheel_radius_error=(0.0,) * 4)

    def to_dict(self) -> dict:
        """The settings as plain data; the per-group breakaway only when set (older files unchanged)."""
        out = dict(self.__dict__)
        out["wheel_radius_error"] = list(self.wheel_radius_error)
        for key in ("breakaway_ratios", "stribeck_velocities"):
            if out[key] is None:
                del out[key]
            else:
                out[key] = list(out[key])
        return out


def parse_breakaway(text: str) -> tuple[str, float, float | None]:
    """``GROUP=RATIO[:W_S]`` -> ``(group, ratio, w_s)`` (``"w=1.3:0.05"``; W_S None when not given):
    breakaway ratio d_s / d_c >= 1 and Stribeck velocity w_s > 0 rad/s of joint group ``l`` (left
    steering), ``r`` (right steering), ``w`` (wheels) or ``all``; a bad string is a ValueError naming
    it and the expected form (``--breakaway``, :meth:`PlantSettings.with_breakaway`)."""
    form = ("expected GROUP=RATIO[:W_S] with GROUP one of l, r, w, all (left steering, right steering, wheels), "
            "RATIO = static / sliding friction >= 1 and W_S the Stribeck velocity > 0 rad/s, e.g. all=1.3:0.05")
    group, sep, values = text.strip().partition("=")
    group = group.strip().lower()
    if not sep:
        raise ValueError(f"--breakaway {text!r}: no '=': {form}")
    if group not in (*BREAKAWAY_GROUPS, "all"):
        raise ValueError(f"--breakaway {text!r}: unknown joint group {group!r}: {form}")
    parts = values.split(":")
    try:
        if not 1 <= len(parts) <= 2:
            raise ValueError("wrong number of fields")
        ratio = float(parts[0])
        w_s = float(parts[1]) if len(parts) == 2 else None
    except ValueError as exc:
        raise ValueError(f"--breakaway {text!r}: {exc}: {form}") from None
    if not (math.isfinite(ratio) and ratio >= 1):
        raise ValueError(f"--breakaway {text!r}: ratio {ratio!r}: expected >= 1 (static >= sliding friction)")
    if w_s is not None and not (math.isfinite(w_s) and w_s > 0):
        raise ValueError(f"--breakaway {text!r}: Stribeck velocity {w_s!r}: expected > 0 rad/s")
    return group, ratio, w_s


def default_unit_mass(params: Parameters, offset: float, mass: float = 30.0) -> float:
    """30 kg per steering unit, capped so that the units' share ``m e^2`` is at most half of C/2."""
    if offset == 0:
        return mass
    return min(mass, 0.25 * min(params.C_l, params.C_r) / offset**2)


def plant_constants(geom: Geometry, params: Parameters, settings: PlantSettings) -> np.ndarray:
    """Constant vector of the compiled plant from geometry, true parameters (eq. 18) and settings."""
    c = np.zeros(_NCONST)
    c[_L], c[_B], c[_A], c[_R], c[_IG] = geom.l, geom.b, geom.a, geom.r, geom.i_G
    e_u = (geom.a if settings.unit_offset is None else settings.unit_offset) if settings.steering_masses else 0.0
    m_u = default_unit_mass(params, e_u) if settings.unit_mass is None else settings.unit_mass
    m_u = m_u if settings.steering_masses else 0.0
    for key, C in ((_JUL, params.C_l), (_JUR, params.C_r)):
        c[key] = C / 2 - m_u * e_u**2
        if c[key] < 0:
            raise ValueError(f"steering units of {m_u} kg at {e_u} m have more inertia about the steering axis "
                             f"({m_u * e_u ** 2:.4g} kg m^2) than C/2 = {C / 2:.4g}: expected a smaller unit mass")
    c[_MU_MASS], c[_EU] = m_u, e_u
    c[_MB] = params.m_ch - 4 * m_u
    if c[_MB] <= 0:
        raise ValueError(f"unit_mass={m_u}: four units weigh more than m_ch={params.m_ch}")
    c[_BW], c[_DVL], c[_DCL], c[_DVR], c[_DCR] = params.B_w, params.d_vl, params.d_cl, params.d_vr, params.d_cr
    c[_DVW], c[_DCW] = params.d_vw, params.d_cw
    c[_CLONG], c[_CLAT], c[_MU] = settings.slip_stiffness_long, settings.slip_stiffness_lat, settings.mu
    c[_FZ] = params.m_ch * GRAVITY / 4
    c[_V0] = settings.slip_velocity
    c[_COUL] = _COULOMB[settings.coulomb]
    c[_VSTICK], c[_EPS] = settings.stick_velocity, EPSILON
    for g, (ratio, w_s) in enumerate(settings.group_breakaway()):
        c[_RATIO + g], c[_VSTRIB + g] = ratio, w_s
    c[_TLIM] = np.inf if settings.torque_limit is None else settings.torque_limit
    c[_KSTOP], c[_DSTOP] = settings.stop_stiffness, settings.stop_damping
    c[_RW:_RW + 4] = geom.r * (1.0 + np.asarray(settings.wheel_radius_error, dtype=float))
    # chassis body inertia: total yaw inertia at alpha = 0 equals C_ch + C_l + C_r
    c[_CB] = 0.0
    M0 = np.zeros((9, 9))
    _mass_matrix(c, np.zeros(2), M0)
    c[_CB] = params.C_ch + params.C_l + params.C_r - M0[2, 2]
    return c



def set_payload(c: np.ndarray, moments: np.ndarray, m_ch: float) -> None:
    """Write a payload (``moments`` = (m_p, S_x, S_y, J_p), payload.py) into the plant constants ``c``
    in place; ``m_ch`` the unloaded chassis mass (the tyres' normal load becomes (m_ch + m_p) g / 4)."""
    c[_PM], c[_PSX], c[_PSY], c[_PJ] = (float(x) for x in moments)
    c[_FZ] = (m_ch + float(moments[0])) * GRAVITY / 4


__all__ = ["GRAVITY", "BREAKAWAY_GROUPS", "PlantSettings", "parse_breakaway", "plant_constants", "plant_step",
           "kinetic_energy", "run_open_loop", "set_payload"]
