"""Causal rows of eq. (19) for the payload tracker: the identification's rows, filtered forward only.

What a controller running at the sample rate can compute at sample k (all arrays are formed in
vectorised passes over a log; each value depends only on samples up to ``k + lookahead``):

1. motor torques aligned to the angle samples (``torque_lead``, as the identification);
2. stage 1: a causal Butterworth low-pass (``FilterSettings``: order 4, 40 rad/s by default;
   ``scipy.signal.sosfilt``, started in its steady state at the first sample) of the six angles AND
   of the four torques;
3. velocities and accelerations by central differences (np.gradient: one sample of look-ahead each,
   two in all), chassis velocities by odometry (eq. 3) with the slip speed of each wheel;
4. stage 2: the same causal low-pass on the 21 entries of Theta (eq. 16) and on the torques once
   more (PARALLEL filtering: both sides of eq. 19 pass the same two filters, so the filters' delay
   shifts both alike and biases nothing but the nonlinear terms);
5. rows: the chassis coordinate of the row's motion mode (eq. 9 on the filtered angles): ``x_ch`` in
   straight and car-like motion (H_2 of eq. 11, which at alpha_v = 0 is the straight one), ``y_ch``
   in lateral motion, ``gamma_ch`` in rotation. Mode 1 (parking) and the steering coordinates carry
   nothing of m_ch and C_ch (their chassis entries of H_k are zero) and are not used. A row is kept
   when its coordinate moves (``|s_dot| >= stiction_threshold``), no wheel slips (slip speed below
   ``slip_threshold``), with the identification's guards around dropped rows on both sides
   (``stiction_guard`` / cut-off s; ``slip_guard`` s): the guard is the rest of the look-ahead. The
   x_ch rows of car-like motion are kinds of their own (7, 8; the tracker gives them the straight rows'
   biases but a noise level of their own: their yaw column misfits wherever the tyres scrub or slip
   laterally in turns, which the no-slip kinematics of eq. (9) do not describe).

Row k: ``z_k = phi_k . (m_ch, C_ch)`` with ``phi_k`` the m_ch and C_ch columns of ``H_k^T Theta`` and
``z_k = H_k^T B u - (H_k^T Theta)_others p_others`` (every other parameter at its identified value).

With the centre-of-mass offset (``com_offset``; :mod:`agvdyn.model_spec`) ``phi_k`` has a third entry,
the column of ``m_ch y_c``: ``H_k^T (-w_dot, -w^2, -a_x)`` over the chassis rows, with ``w^2 =
gamma_dot^2`` through the same two filters (one more channel of the second), formed in car-like rows
only, as the identification forms it: in straight, lateral and rotation motion the kinematics make
it zero (no rotation with translation), and what the measured signals would give there is noise.
``m_ch x_c`` has no column: it cancels in every mode (in car-like rows ``-w^2 + kappa a_y = 0``), so
x_c is not identifiable (the tracker reports it with an infinite std).

Delay: a row describes the vehicle as it was ``group_delay`` s earlier (the two filters' group delay
at low frequency, 2 x 2.61 / omega_g = 131 ms at 40 rad/s, order 4) and is complete ``lookahead``
samples after its own time (2 for the differences plus the largest guard). Change times are stated
compensated by the group delay; detection times are those at which the row was complete.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agvdyn.dynamics import project_signals, regressor_signals
from agvdyn.kinematics import Mode, detect_mode, kinematic_model, nominal_steering
from agvdyn.odometry import odometry_with_slip
from agvdyn.platform import PARAMETER_NAMES, Geometry, Parameters
from agvdyn.row_rules import RowSettings, guarded_mask

__all__ = ["OnlineRows", "causal_rows", "causal_lowpass", "group_delay", "ROW_KINDS", "BIAS_KINDS",
           "COORDINATE_OF_KIND", "TRACKED"]

#: Tracked parameters (the columns of phi), in this order.
TRACKED = ("m_ch", "C_ch")
#: Kinds of row (index = kind code; 0: no row): the chassis coordinate and the sign of its velocity
#: (each of the first six has its own bias in the tracker: torque offsets and Coulomb friction the held
#: values miss); 7, 8: the x_ch rows of car-like motion (straight: 1, 2), with the biases of x_ch+ and x_ch-.
ROW_KINDS = ("none", "x_ch+", "x_ch-", "y_ch+", "y_ch-", "gamma_ch+", "gamma_ch-", "x_ch+ car-like", "x_ch- car-like")
#: The kinds with a bias of their own (the tracker's states after m_ch and C_ch).
BIAS_KINDS = ROW_KINDS[1:7]
#: Coordinate of each kind (1: x_ch, 2: y_ch, 3: gamma_ch; 0: no row).
COORDINATE_OF_KIND = np.array([0, 1, 1, 2, 2, 3, 3, 1, 1])
_KIND_OF_MODE = {Mode.STRAIGHT: 1, Mode.CAR_LIKE: 1, Mode.LATERAL: 2, Mode.ROTATION: 3}
_DIFFERENCE_LOOKAHEAD = 2


@dataclass(frozen=True, eq=False)
class OnlineRows:
    """Rows of one log: ``t`` (N,), ``phi`` (N, 2) m_ch and C_ch columns (N, 3 with m_ch y_c's), ``z`` (N,)
    the rest of the equation, ``kind`` (N,) int8 codes of :data:`ROW_KINDS` (0: no row at this sample),
    ``group_delay`` s, ``lookahead`` samples, ``dt`` s."""

    t: np.ndarray
    phi: np.ndarray
    z: np.ndarray
    kind: np.ndarray
    group_delay: float
    lookahead: int
    dt: float

    @property
    def n(self) -> int:
        return self.t.size


def causal_lowpass(x: np.ndarray, sos: np.ndarray) -> np.ndarray:
    """Forward-only filter of ``x`` (N, C) along axis 0, started in the steady state of its first row."""
    from scipy.signal import sosfilt, sosfilt_zi

    zi = sosfilt_zi(sos)[:, :, None] * x[0][None, None, :]
    return sosfilt(sos, x, axis=0, zi=zi)[0]


def group_delay(sos: np.ndarray, dt: float) -> float:
    """Group delay (s) of the sections ``sos`` at low frequency (1e-3 of Nyquist)."""
    from scipy.signal import group_delay as gd, sos2tf

    w, d = gd(sos2tf(sos), w=[1e-3 * math.pi])
    return float(d[0]) * dt


def _guard(keep: np.ndarray, samples: int) -> np.ndarray:
    return guarded_mask(keep, samples) if samples > 0 else keep


def _row_kinds(geom: Geometry, alpha: np.ndarray, q_dot: np.ndarray, slip: np.ndarray, rules: RowSettings,
               slip_threshold: float, dt: float) -> tuple[np.ndarray, int, np.ndarray]:
    """Kind code (N,) of each sample's row (:data:`ROW_KINDS`) after the mode, stiction and slip rules, the
    guard in samples, and the motion mode (N,)."""
    mode = detect_mode(geom, alpha, tolerance=rules.mode_tolerance)
    kind = np.zeros(mode.size, dtype=np.int8)
    velocity = np.zeros(mode.size)
    for m, k in _KIND_OF_MODE.items():
        sel = mode == int(m)
        kind[sel] = k
        velocity[sel] = q_dot[sel, (0, 0, 1, 2)[k]]
    speed = np.abs(velocity)
    guard = rules.guard_samples(rules.stiction_guard, dt)
    slip_guard = int(round(rules.slip_guard / dt))
    moving = (kind > 0) & (speed >= rules.stiction_threshold)
    no_slip = _guard(slip.max(axis=1) < slip_threshold, slip_guard)
    keep = np.zeros(mode.size, dtype=bool)
    for k in (1, 2, 3):
        keep |= _guard(moving & (kind == k), guard)
    kind[~(keep & no_slip)] = 0
    signed = np.where(kind > 0, 2 * kind - 1 + (velocity < 0), 0).astype(np.int8)
    signed[(mode == int(Mode.CAR_LIKE)) & (kind == 1)] += 6  # the car-like x_ch rows: kinds 7, 8
    return signed, max(guard, slip_guard), mode


def _project(geom: Geometry, kind: np.ndarray, alpha: np.ndarray, signals: np.ndarray, torque: np.ndarray,
             params: Parameters, car_like: np.ndarray | None = None,
             w2: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """phi (N, 2) and z (N,) of the rows (zeros where kind == 0); with ``w2`` (the filtered gamma_dot^2)
    phi (N, 3): the m_ch y_c column in the ``car_like`` rows (:func:`offset_column`)."""
    n = kind.size
    phi, z = np.zeros((n, 2 if w2 is None else 3)), np.zeros(n)
    p = params.to_vector()
    cols = [PARAMETER_NAMES.index(name) for name in TRACKED]
    others = np.ones(p.size, dtype=bool)
    others[cols] = False
    for k, mode, c in ((1, Mode.CAR_LIKE, 1), (2, Mode.LATERAL, 0), (3, Mode.ROTATION, 0)):
        idx = np.flatnonzero(COORDINATE_OF_KIND[kind] == k)
        if idx.size == 0:
            continue
        if mode is Mode.CAR_LIKE:  # straight is car-like motion at alpha_v = 0 (H_2 then equals H_straight)
            H = kinematic_model(geom, mode, alpha[idx], tolerance=math.inf)[:, :, c:c + 1]
        else:
            H = kinematic_model(geom, mode, nominal_steering(geom, mode)[None])[:, :, c:c + 1]
        Y = project_signals(H, signals[idx])[:, 0, :]
        tau = geom.i_G * np.einsum("nw,nw->n", np.broadcast_to(H[:, 5:, 0], (idx.size, 4)), torque[idx])
        phi[idx, :2] = Y[:, cols]
        z[idx] = tau - Y[:, others] @ p[others]
        if w2 is not None and k == 1:
            turn = car_like[idx]
            phi[idx[turn], 2] = offset_column(H[turn, :, 0], signals[idx[turn]], w2[idx[turn]])
    return phi, z


def offset_column(H: np.ndarray, signals: np.ndarray, w2: np.ndarray) -> np.ndarray:
    """The m_ch y_c column (N,) of rows of one coordinate with kinematic column ``H`` (N, 9): ``H^T`` of the
    chassis entries ``(-w_dot, -w^2, -a_x)`` (model_spec's com-offset rows; ``signals`` the filtered
    entries of Theta, ``w2`` the filtered ``gamma_dot^2``), as the identification forms it
    (``identification/_model_kernels.py``)."""
    return -H[:, 0] * signals[:, 2] - H[:, 1] * w2 - H[:, 2] * signals[:, 0]


def causal_rows(t: np.ndarray, alpha: np.ndarray, beta: np.ndarray, torque: np.ndarray, geom: Geometry,
                params: Parameters, *, rules: RowSettings = RowSettings(), torque_lead: float = 0.0,
                slip_threshold: float = 0.05, com_offset: bool = False) -> OnlineRows:
    """Rows of the tracker from one continuous log (module docstring). ``params``: every parameter
    but m_ch and C_ch is held at its value here (the identified ones). ``com_offset``: a third column,
    m_ch y_c's (car-like rows only; ``gamma_dot^2`` one more channel of the second filter)."""
    t = np.asarray(t, dtype=float)
    if t.size < 8:
        raise ValueError(f"a log of {t.size} samples: the tracker needs at least 8")
    dt = float(np.median(np.diff(t)))
    u = np.asarray(torque, dtype=float)
    if torque_lead:
        u = u.copy()
        u[1:] = (1.0 - torque_lead) * u[1:] + torque_lead * u[:-1]
    sos = rules.filter.sos(dt)
    f1 = causal_lowpass(np.column_stack([alpha, beta, u]), sos)
    alpha_f = np.clip(f1[:, :2], -math.pi / 2, math.pi / 2)
    rates = np.gradient(f1[:, :6], dt, axis=0)
    chassis, slip = odometry_with_slip(geom, alpha_f, rates[:, :2], rates[:, 2:])
    q_dot = np.column_stack([chassis, rates])
    q_ddot = np.gradient(q_dot, dt, axis=0)
    channels = [regressor_signals(q_dot, q_ddot, rules.epsilon), f1[:, 6:]]
    if com_offset:
        channels.append(np.square(q_dot[:, 2:3]))
    f2 = causal_lowpass(np.column_stack(channels), sos)
    kind, guard, mode = _row_kinds(geom, alpha_f, q_dot, slip, rules, slip_threshold, dt)
    if com_offset:
        phi, z = _project(geom, kind, alpha_f, f2[:, :21], f2[:, 21:25], params, mode == int(Mode.CAR_LIKE), f2[:, 25])
    else:
        phi, z = _project(geom, kind, alpha_f, f2[:, :21], f2[:, 21:], params)
    return OnlineRows(t, phi, z, kind, 2 * group_delay(sos, dt), _DIFFERENCE_LOOKAHEAD + guard, dt)
