"""The model extensions in the row pass (issue 30; the laws and names are :mod:`agvdyn.model_spec`'s).

A resolved :class:`~agvdyn.model_spec.ModelSpec` (every nonlinear value known) changes the rows of
eq. (19) in three ways, each only when the model has it (the paper's rows never pass here):

* ``delay``: the motor torques of a stretch are read at ``t + delay_s`` (:func:`delayed_torque`,
  linear interpolation between samples, after which ``torque_lead`` aligns them as before); rows
  whose shifted time falls outside the stretch join its filter edges (dropped);
* ``friction: stribeck``: per joint ``e(w) tanh(w / epsilon)``, ``e = exp(-(w / w_s)^2)``
  (:func:`agvdyn.model_spec.breakaway_weight`), from the same once-filtered joint rates as the tanh
  entries of Theta; six more channels of the second filter (PARALLEL: the same filter as Theta);
* ``com_offset``: ``w^2`` (``w = gamma_dot``, the odometry's yaw rate) as one more channel; the
  columns are formed in car-like rows only (translation with rotation), zero in the other modes, whose
  kinematics have no rotation with translation (there the measured signals would give noise columns
  that look determined). Even in car-like rows the ``m_ch x_c`` column cancels (``-w^2 + kappa a_y = 0``:
  the reference point has no lateral velocity): :mod:`.model_fit` holds x_c, ``inf`` std.

:func:`model_projection_columns` projects them (:func:`._model_kernels.model_projection`) into the
columns ``ModelSpec.linear_names`` of each row: ``d_sl, d_sr, d_sw`` (the ``d_c`` columns become
``H_k^T [(1 - e) tanh]``) and ``m_ch x_c, m_ch y_c``.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from agvdyn.identification._model_kernels import model_projection
from agvdyn.kinematics import Mode
from agvdyn.model_spec import PAPER_MODEL, ModelSpec, breakaway_weight

__all__ = ["resolved_model", "model_channels", "delay_shift", "delayed_torque", "stretch_torque",
           "fill_model_channels", "model_projection_columns", "stribeck_support", "SUPPORT_SHARE"]

#: A row supports a joint group's breakaway level where ``e = exp(-(w/w_s)^2)`` of its own rate is above
#: this share (``|w| < 0.83 w_s``): there the friction is mostly the breakaway excess.
SUPPORT_SHARE = 0.5
#: Channels per extension: the six joints' ``e tanh`` (stribeck), ``w^2`` (com_offset).
STRIBECK_CHANNELS = 6
COM_CHANNELS = 1


def resolved_model(model: Any) -> ModelSpec:
    """``model`` when it is a resolved :class:`ModelSpec`; a ValueError naming what is left to search
    (a delay ``'auto'``, Stribeck velocities not given) or the wrong type otherwise."""
    if model is None:
        return PAPER_MODEL
    if not isinstance(model, ModelSpec):
        raise ValueError(f"model={model!r}: expected an agvdyn.model_spec.ModelSpec")
    open_values = ([f"delay={model.delay!r}"] if model.delay == "auto" else []) + \
                  (["stribeck_velocities=None"] if model.stribeck and model.stribeck_velocities is None else [])
    if open_values:
        raise ValueError(f"model {model.label}: {', '.join(open_values)} must be searched: identify fits a resolved "
                         "model (a delay in seconds, the Stribeck velocities given); use the search "
                         "(agvdyn.identification.identify_model) for 'auto' and unknown Stribeck velocities")
    return model


def model_channels(model: ModelSpec) -> int:
    """Channels the model adds to the second filter (0 for the paper's model)."""
    return STRIBECK_CHANNELS * model.stribeck + COM_CHANNELS * model.com_offset


def delay_shift(delay_s: float, dt: float) -> float:
    """The delay in samples of ``dt`` (within 1e-9 of a whole number: that number, an exact shift)."""
    s = delay_s / dt
    whole = round(s)
    return float(whole) if abs(s - whole) <= 1e-9 * max(1.0, abs(s)) else s


def delayed_torque(torque: np.ndarray, shift: float) -> tuple[np.ndarray, int, int]:
    """Torques (n, 4) read ``shift`` samples later, ``u(t_j + shift dt)`` by linear interpolation
    between samples, and how many rows at the front and at the back fall outside the stretch (their
    values are the nearest end's: the rows are dropped)."""
    n = torque.shape[0]
    first = math.floor(shift)
    frac = shift - first
    index = np.arange(n) + first
    out = torque[np.clip(index, 0, n - 1)]
    if frac > 0:
        out = (1.0 - frac) * out + frac * torque[np.clip(index + 1, 0, n - 1)]
    return out, min(n, max(0, -first)), min(n, max(0, first + (frac > 0)))


def stretch_torque(torque: np.ndarray, model: ModelSpec, dt: float) -> tuple[np.ndarray, int, int]:
    """A stretch's torque columns as the row pass reads them: ``torque`` itself (no delay), else
    :func:`delayed_torque` by the model's delay; with the rows outside the stretch at each end."""
    if model.delay == 0.0:
        return torque, 0, 0
    return delayed_torque(np.asarray(torque, dtype=float), delay_shift(float(model.delay), dt))


def fill_model_channels(model: ModelSpec, q_dot: np.ndarray, tanh: np.ndarray, out: np.ndarray) -> None:
    """The model's channels into ``out`` (n, :func:`model_channels`): ``e tanh`` of the steering
    left, right and the four wheels (``q_dot[:, 3:9]``, their ``tanh(q_dot / epsilon)`` ``tanh``)
    with ``e = exp(-(w / w_s)^2)`` of the joint's group, then ``gamma_dot^2``."""
    col = 0
    if model.stribeck:
        w_sl, w_sr, w_sw = model.stribeck_velocities
        out[:, :STRIBECK_CHANNELS] = breakaway_weight(q_dot[:, 3:9], np.array([w_sl, w_sr, w_sw, w_sw, w_sw, w_sw]))
        out[:, :STRIBECK_CHANNELS] *= tanh
        col = STRIBECK_CHANNELS
    if model.com_offset:
        np.square(q_dot[:, 2], out=out[:, col])


def model_projection_columns(model: ModelSpec, mode: np.ndarray, av: np.ndarray, runs: np.ndarray, count: int,
                             signals: np.ndarray, extra: np.ndarray, h_const: np.ndarray, dofs: np.ndarray,
                             geometry: Any, limit: float, Y: np.ndarray, X: np.ndarray) -> None:
    """The model's columns ``X`` (n, 2, q) of the runs of a stretch (:func:`._model_kernels.model_projection`),
    the breakaway share taken out of the ``d_c`` columns of ``Y``."""
    model_projection(mode, av, runs, count, signals, extra, h_const, dofs, geometry.l, geometry.b, geometry.a,
                     geometry.r, limit, model.stribeck, model.com_offset, Y, X)


def stribeck_support(model: ModelSpec, q_dot: np.ndarray, first: int, blocks: Any) -> dict[str, int]:
    """Per joint group (``l``, ``r``, ``w``) the kept rows of ``blocks`` (a stretch's; ``q_dot`` its once-filtered
    joint rates, ``first`` its first row in the log) whose own joint rate is in the Stribeck range,
    ``e(w) > SUPPORT_SHARE``, and moving (a wheel row counts when any wheel does; the steering only in the
    modes that move it: 1 and 2). Without such rows a group's ``d_s`` column holds only the filter's tails
    of stick phases (docs/identification.md, "Breakaway friction"): :mod:`.model_fit` then leaves ``d_s``
    undetermined."""
    if not model.stribeck:
        return {}
    w_s = np.array(model.stribeck_velocities)[[0, 1, 2, 2, 2, 2]]
    out = {"l": 0, "r": 0, "w": 0}
    for b in blocks:
        rates = np.abs(q_dot[b.sample - first, 3:9])
        inside = (rates > 0) & (breakaway_weight(rates, w_s) > SUPPORT_SHARE)
        out["w"] += int((inside[:, 2:].any(axis=1) & b.keep.any(axis=1)).sum())
        if b.mode is Mode.PARKING:  # each side's rows: its own coordinate kept
            out["l"] += int((inside[:, 0] & b.keep[:, 0]).sum())
            out["r"] += int((inside[:, 1] & b.keep[:, 1]).sum())
        elif b.mode is Mode.CAR_LIKE:  # both sides follow the virtual steering angle, the second coordinate
            out["l"] += int((inside[:, 0] & b.keep[:, 1]).sum())
            out["r"] += int((inside[:, 1] & b.keep[:, 1]).sum())
    return out
