"""The regressor columns of the model beyond the paper (issue 30) on a planned segment, for the
planner's predicted standard deviations (:func:`.evaluation.evaluate_sequence` with ``model=``).

On the exact planned motion (no filter) and with the equations of :mod:`agvdyn.model_spec`:

* ``stribeck``: per joint group the breakaway column ``H^T [e tanh(w/eps)]`` (``e = exp(-(w/w_s)^2)``; none
  for a level the spec holds);
  the Coulomb column becomes ``H^T [(1 - e) tanh]`` (the identification's parametrisation: ``d_s``
  the static level); ``w_s`` from the model's values (or its spec, else the middle of its range);
* ``com_offset``: the column of ``m_ch y_c`` (rows ``(-w_dot, -w^2, -a_x)`` on ``(x, y, gamma)``);
  ``m_ch x_c``'s column is zero in every mode of this vehicle, so ``x_c`` is undetermined (inf);
* ``delay``: the linearisation of ``H^T B u(t + tau)`` about the planned torques, the column
  ``-H^T B u_dot`` of ``tau`` (u from the feed-forward of eq. 21 with the given parameters).
"""
from __future__ import annotations

import math

import numpy as np

from agvdyn.model_spec import BREAKAWAY_NAMES, FRICTION_GROUPS, ModelParameters, ModelSpec, breakaway_weight
from agvdyn.platform import EPSILON, PARAMETER_NAMES, Geometry

__all__ = ["extra_names", "stribeck_velocities", "segment_columns"]

_DC = {g: PARAMETER_NAMES.index(dc) for g, (_, dc) in FRICTION_GROUPS.items()}
_ROWS = {"l": (3,), "r": (4,), "w": (5, 6, 7, 8)}


def extra_names(spec: ModelSpec) -> tuple[str, ...]:
    """Names of the predicted extra stds, in column order: ``d_sl, d_sr, d_sw`` (those not ``held``), ``y_c``,
    ``delay_s``."""
    return (tuple(n for n in BREAKAWAY_NAMES if spec.stribeck and n not in spec.held)
            + (("y_c",) if spec.com_offset else ()) + (("delay_s",) if spec.delay != 0.0 else ()))


def stribeck_velocities(model: ModelParameters | ModelSpec) -> tuple[float, float, float]:
    """``(w_sl, w_sr, w_sw)`` rad/s: the model's values, its spec's, else the geometric middle of its range."""
    spec = model.spec if isinstance(model, ModelParameters) else model
    if isinstance(model, ModelParameters) and all(f"w_s{g}" in model.extra for g in "lrw"):
        return tuple(model.extra[f"w_s{g}"] for g in "lrw")
    if spec.stribeck_velocities is not None:
        return spec.stribeck_velocities
    return (math.sqrt(spec.stribeck_range[0] * spec.stribeck_range[1]),) * 3


def segment_columns(geom: Geometry, spec: ModelSpec, w_s: tuple[float, float, float], H: np.ndarray,
                    qd: np.ndarray, qdd: np.ndarray, u: np.ndarray, dt: float, Y: np.ndarray) -> np.ndarray:
    """Extra columns ``(N, k, n_extra)`` of a segment (H ``(N, 9, k)``, motion ``(N, 9)``, planned motor
    torques ``u (N, 4)``); ``Y`` ``(N, k, 11)`` the projected regressor, whose Coulomb columns are
    changed in place to ``H^T [(1 - e) tanh]`` when the model has the Stribeck law."""
    cols = []
    if spec.stribeck:
        for g, w in zip("lrw", w_s):
            if f"d_s{g}" in spec.held:  # at the paper's law: its Coulomb column stays the paper's
                continue
            rows = list(_ROWS[g])
            rate = qd[:, rows]
            signal = breakaway_weight(rate, w) * np.tanh(rate / EPSILON)  # (N, joints)
            col = np.einsum("njk,nj->nk", H[:, rows, :], signal)
            Y[:, :, _DC[g]] -= col
            cols.append(col)
    if spec.com_offset:
        vx, vy, w = qd[:, 0], qd[:, 1], qd[:, 2]
        a_x = qdd[:, 0] - vy * w
        force = np.stack([-qdd[:, 2], -w * w, -a_x], axis=1)  # m_ch y_c on (x, y, gamma)
        cols.append(np.einsum("njk,nj->nk", H[:, :3, :], force))
    if spec.delay != 0.0:
        u_dot = np.gradient(u, dt, axis=0) if u.shape[0] > 2 else np.zeros_like(u)
        cols.append(-geom.i_G * np.einsum("njk,nj->nk", H[:, 5:, :], u_dot))
    if not cols:
        return np.zeros(H.shape[:1] + (H.shape[2], 0))
    return np.stack(cols, axis=2)
