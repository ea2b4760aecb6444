"""Row weights of a phase (validity, reversals, noise growth) and the smooth helpers of the objective."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agvdyn.trajectories.planner.settings import PlanSettings


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1 + np.tanh(0.5 * x))


@dataclass(frozen=True, eq=False)
class _Weights:
    """Per-row weights of a phase and their partial derivatives in v and a."""

    wU: np.ndarray
    wO: np.ndarray
    pen: np.ndarray
    wU_v: np.ndarray
    wU_a: np.ndarray
    wO_v: np.ndarray
    wO_a: np.ndarray
    pen_v: np.ndarray
    pen_a: np.ndarray


def _row_weights(v: np.ndarray, a: np.ndarray, th: float, knee: float, st: PlanSettings,
                 saturation: float, guard: float) -> _Weights:
    """Weights of the rows of a phase (``wU``: in F and in cond; ``wO``: in Omega, the rows' variance)
    and the penalty per second (``pen``), smooth in the velocity v and acceleration a.

    * validity ``wv``: a smooth step at ``validity`` times the stiction threshold ``th``;
    * contamination ``k``: a row the identification keeps (more than ``guard`` s after the
      velocity passed ``th``, :meth:`PlanSettings.guard`) but within
      ``reversal_window`` of a velocity reversal: there the
      stick of the reversal, spread by the zero-phase filter, is in the torques. With the
      acceleration a near the reversal, such rows have ``th + guard |a| <= |v| < window |a|``
      (empty for slow reversals, ``|a| < th / (window - guard)``). They earn no credit and cost
      ``reversal_penalty`` per share of the time;
    * the time below the validity speed costs ``band_penalty`` per share;
    * the row's variance factor ``q = 1 + g / (1 + g / saturation)``, ``g = (a / knee)^4``
      (:class:`NoiseLevels`): ``wO = wU q``.
    """
    V, A = np.abs(v), np.abs(a)
    sv, sa = np.sign(v), np.sign(a)
    v_ok = st.validity * th
    width = st.validity_width * v_ok
    wv = _sigmoid((V - v_ok) / width)
    dwv = wv * (1 - wv) / width
    d = 0.2 * th
    k1 = _sigmoid((V - th - guard * A) / d)
    k2 = _sigmoid((st.reversal_window * A - V) / d)
    k = k1 * k2
    dk1 = k1 * (1 - k1) / d
    dk2 = k2 * (1 - k2) / d
    k_V = dk1 * k2 - k1 * dk2
    k_A = -guard * dk1 * k2 + st.reversal_window * k1 * dk2
    if math.isfinite(knee):
        g4 = (a / knee) ** 4
        den = 1 + g4 / saturation
        q = 1 + g4 / den
        q_a = 4 * a**3 / knee**4 / den**2
    else:
        q, q_a = np.ones_like(a), np.zeros_like(a)
    wU = wv * (1 - k)
    wU_V = dwv * (1 - k) - wv * k_V
    wU_A = -wv * k_A
    pen = st.band_penalty * (1 - wv) + st.reversal_penalty * k
    return _Weights(wU=wU, wO=wU * q, pen=pen, wU_v=sv * wU_V, wU_a=sa * wU_A, wO_v=sv * wU_V * q,
                    wO_a=sa * wU_A * q + wU * q_a,
                    pen_v=sv * (-st.band_penalty * dwv + st.reversal_penalty * k_V),
                    pen_a=sa * st.reversal_penalty * k_A)


def _softplus(x: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Smooth max(x, 0) of the given width and its derivative."""
    y = x / width
    sp = width * np.logaddexp(0.0, y)
    return sp, _sigmoid(y)


def _log_cond(U: np.ndarray) -> tuple[float, np.ndarray]:
    """log cond of the column-scaled matrix D U D (D = diag(U)^-1/2) and its derivative in U."""
    d = 1 / np.sqrt(np.diag(U))
    S = U * np.outer(d, d)
    lam, V = np.linalg.eigh(S)
    out = np.zeros_like(U)
    for idx, sign in ((-1, 1.0), (0, -1.0)):
        v = V[:, idx]
        dv = d * v
        grad = np.outer(dv, dv) - lam[idx] * np.diag(v**2 * d**2)
        out += sign * grad / lam[idx]
    return float(np.log(lam[-1] / lam[0])), out
