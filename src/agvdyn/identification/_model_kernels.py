"""Compiled kernel of the model extensions' rows (:mod:`agvdyn.model_spec`, issue 30): the regression
columns the extensions add, projected like the paper's columns by the same ``H_k`` of every row.

* :func:`model_projection`: for every run of one mode that :func:`._kernels.stretch_projection`
  found, per row and generalized coordinate, the breakaway columns ``H_k^T [e tanh]`` of the left
  steering, the right steering and the wheels (the ``d_c`` columns of ``Y`` become
  ``H_k^T [(1 - e) tanh]``: ``d_s`` is estimated directly) and the centre-of-mass columns of
  ``m_ch x_c`` (chassis rows ``(-w^2, w_dot, a_y)``) and ``m_ch y_c`` (``(-w_dot, -w^2, -a_x)``) in the
  car-like rows (mode 2, translation with rotation); in the other modes the mode's kinematics make
  them zero (no rotation with translation): what the measured signals would give there is noise.

Runs only when a model has such columns: the paper's rows never enter it.
"""
from __future__ import annotations

import numpy as np

from agvdyn._jit import njit
from agvdyn._numba_cache import drop_stale_cache
from agvdyn.kinematics import car_like_model_into, constraints, models

drop_stale_cache(__file__, constraints.__file__, models.__file__)

__all__ = ["model_projection"]


@njit(cache=True, nogil=True, inline="always")
def _model_row(H, dof, sig, extra, j, stribeck, com, turning, Y, X):  # pragma: no cover - compiled
    """Row j's extension columns ``X[j, c]`` from the filtered signals ``sig[j]`` (entries of Theta)
    and ``extra[j]`` (``e tanh`` of the six joints when ``stribeck``, then ``w^2`` when ``com``);
    the breakaway share taken out of the ``d_c`` columns of ``Y[j, c]``; the centre-of-mass columns
    zero unless ``turning`` (a car-like row)."""
    for c in range(dof):
        col = 0
        if stribeck:
            left = H[3, c] * extra[j, 0]
            right = H[4, c] * extra[j, 1]
            wheels = 0.0
            for w in range(4):
                wheels += H[5 + w, c] * extra[j, 2 + w]
            X[j, c, 0], X[j, c, 1], X[j, c, 2] = left, right, wheels
            Y[j, c, 2] -= left
            Y[j, c, 5] -= right
            Y[j, c, 9] -= wheels
            col = 3
        if com and turning:
            w2 = extra[j, 6 if stribeck else 0]
            X[j, c, col] = -H[0, c] * w2 + H[1, c] * sig[j, 2] + H[2, c] * sig[j, 1]
            X[j, c, col + 1] = -H[0, c] * sig[j, 2] - H[1, c] * w2 - H[2, c] * sig[j, 0]
        elif com:
            X[j, c, col] = X[j, c, col + 1] = 0.0


@njit(cache=True, nogil=True)
def model_projection(mode, av, runs, count, sig, extra, h_const, dofs, l, b, a, r, limit, stribeck, com, Y, X):
    # pragma: no cover - compiled
    """The extension columns ``X`` (n, 2, q) of the rows of the ``count`` runs ``runs`` (start, stop)
    of a stretch (as :func:`._kernels.stretch_projection` found them): ``H_k`` constant per mode
    (``h_const``), or of the virtual angle ``av`` (clipped to ``limit``) in mode 2. ``Y`` (n, 2, 11)
    gets its ``d_c`` columns reduced by the breakaway columns when ``stribeck``."""
    H = np.empty((9, 2))
    dH = np.empty((9, 2))
    for k in range(count):
        start, stop = runs[k, 0], runs[k, 1]
        m = mode[start]
        dof = dofs[m]
        if m != 2:
            for i in range(9):
                for c in range(2):
                    H[i, c] = h_const[m, i, c]
        for j in range(start, stop):
            if m == 2:
                car_like_model_into(l, b, a, r, min(max(av[j], -limit), limit), H, dH)
            _model_row(H, dof, sig, extra, j, stribeck, com, m == 2, Y, X)
