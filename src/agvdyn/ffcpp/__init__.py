"""The C++ feed-forward (``cpp/``, library ``agvdyn_ff``) from Python: eq. (21) on the same inputs as
:func:`agvdyn.dynamics.feedforward_torques`, which stays the reference; and the C++ payload tracker
(``agvdyn_ff::PayloadTracker``) on the causal rows of :mod:`agvdyn.online.rows`, the twin of
:func:`agvdyn.online._kernels.track_rows` (:func:`track_rows`; ``agvdyn.online.cpp`` builds the
replay of ``agvdyn.online.track`` on it).

The compiled extension ``agvdyn.ffcpp._core`` is built by ``pip install`` (CMake + nanobind through
``agvdyn._ffbuild``, see ``docs/cpp.md``); ``import agvdyn`` never needs it. Without it, :func:`extension`
raises :class:`CppEngineUnavailable` saying how to get it.

Example
-------
>>> from agvdyn.ffcpp import feedforward_torques          # doctest: +SKIP
>>> u = feedforward_torques(PROTOTYPE, PAPER_PARAMETERS, "2", alpha, s_dot, s_ddot)   # doctest: +SKIP
"""
from __future__ import annotations

from types import ModuleType
from typing import Literal

import numpy as np

from agvdyn.kinematics import MODE_TOLERANCE, STOP_TOLERANCE, Mode
from agvdyn.kinematics.constraints import _rows
from agvdyn.model_spec import FRICTION_GROUPS, ModelParameters
from agvdyn.platform import EPSILON, Geometry, Parameters

__all__ = ["Engine", "ENGINES", "CppEngineUnavailable", "available", "extension", "check_engine",
           "feedforward_torques", "joint_motion", "trajectory_feedforward", "read_parameter_file", "track_rows",
           "TRACKER_SETTINGS"]

#: Implementations of the feed-forward of eq. (21): ``python`` (the reference) or ``cpp``.
Engine = Literal["python", "cpp"]
ENGINES: tuple[str, ...] = ("python", "cpp")

#: Messages of the C++ status codes (agvdyn_ff::Status), for errors raised here.
_EXPECTED = {
    "unknown_mode": "expected mode 1, 2, 3, 4 or straight",
    "non_finite_input": "expected finite alpha, s_dot and s_ddot",
    "beyond_stop": f"expected |alpha| <= pi/2 + {STOP_TOLERANCE} (mechanical stops)",
    "not_in_mode": "expected the configuration of the mode (eq. 9) within the mode tolerance",
    "singular": "N^T B has no full rank (a = 0: the wheels cannot steer the passive steering)",
}


class CppEngineUnavailable(ImportError):
    """The C++ extension agvdyn.ffcpp._core is not installed (no compiler at install time, or an
    installation from a source tree without the build)."""


def check_engine(engine: str) -> Engine:
    """``engine`` if it is one of :data:`ENGINES`, else ValueError listing them."""
    if engine not in ENGINES:
        raise ValueError(f"engine={engine!r}: expected one of {list(ENGINES)}")
    return engine  # type: ignore[return-value]


def extension() -> ModuleType:
    """The compiled module ``agvdyn.ffcpp._core``; CppEngineUnavailable with what to do when missing."""
    try:
        from agvdyn.ffcpp import _core
    except ImportError as exc:
        raise CppEngineUnavailable(
            "the C++ feed-forward engine is not available: agvdyn was installed without its extension "
            f"agvdyn.ffcpp._core ({exc}). It is built by `pip install -e .` (what `make test` runs) "
            "with a C++17 compiler and CMake >= 3.18 (Debian: apt-get install g++ cmake); reinstall "
            "after installing them, or use --engine python"
        ) from exc
    return _core


def available() -> bool:
    """True when the C++ extension can be imported."""
    try:
        extension()
    except CppEngineUnavailable:
        return False
    return True


def _extension(params: Parameters | ModelParameters) -> dict:
    """The keyword arguments of ``_core.Model`` for the model beyond the paper (``agvdyn_ff::Extension``)."""
    if not isinstance(params, ModelParameters):
        return {}
    groups = [params.friction(g) for g in FRICTION_GROUPS]
    return {"stribeck": params.spec.stribeck, "d_s": tuple(float(g[2]) for g in groups),
            "w_s": tuple(float(g[3]) for g in groups), "com_offset": params.spec.com_offset,
            "x_c": float(params.value("x_c")), "y_c": float(params.value("y_c")), "delay_s": float(params.delay_s)}


def _model(geom: Geometry, params: Parameters | ModelParameters, epsilon: float, tolerance: float):
    core = extension()
    values = params.parameters if isinstance(params, ModelParameters) else params
    return core.Model((geom.l, geom.b, geom.a, geom.r, geom.i_G), [float(v) for v in values.to_vector()],
                      float(epsilon), float(tolerance), float(STOP_TOLERANCE), **_extension(params))


def _torques(model, core, mode: Mode, alpha, s_dot, s_ddot, *, motion: bool = False):
    alpha = np.ascontiguousarray(np.atleast_2d(np.asarray(alpha, dtype=float)))
    if alpha.ndim != 2 or alpha.shape[1] != 2:
        raise ValueError(f"alpha of shape {alpha.shape}: expected (N, 2) = (alpha_l, alpha_r)")
    n = alpha.shape[0]
    sd = np.ascontiguousarray(_rows(s_dot, n, mode.dof, "s_dot"))
    sdd = np.ascontiguousarray(_rows(s_ddot, n, mode.dof, "s_ddot"))
    u = np.empty((n, 4))
    q_dot = np.empty((n if motion else 0, 9))
    q_ddot = np.empty((n if motion else 0, 9))
    status, row = model.feedforward(int(mode), alpha, sd, sdd, u, q_dot, q_ddot)
    if row >= 0:
        name = core.status_name(status)
        raise ValueError(
            f"C++ feed-forward, mode {mode.label} ({mode.name.lower()}), row {row}: alpha = "
            f"({alpha[row, 0]:.6g}, {alpha[row, 1]:.6g}) rad, s_dot = {sd[row].tolist()}, s_ddot = {sdd[row].tolist()}: "
            f"{name}: {_EXPECTED.get(name, 'invalid input')}"
        )
    return (u, q_dot, q_ddot) if motion else u


def feedforward_torques(geom: Geometry, params: Parameters | ModelParameters, mode, alpha, s_dot, s_ddot, *,
                        epsilon: float = EPSILON, tolerance: float = MODE_TOLERANCE) -> np.ndarray:
    """Motor torques u ``(N, 4)`` of eq. (21) computed by the C++ library; same arguments (a
    :class:`~agvdyn.model_spec.ModelParameters` for the model beyond the paper), same result (to
    round-off) and the same refusals (ValueError) as :func:`agvdyn.dynamics.feedforward_torques`."""
    mode = Mode.from_label(mode)
    return _torques(_model(geom, params, epsilon, tolerance), extension(), mode, alpha, s_dot, s_ddot)


def joint_motion(geom: Geometry, mode, alpha, s_dot, s_ddot, *, tolerance: float = MODE_TOLERANCE):
    """``(q_dot, q_ddot)`` ``(N, 9)`` of eq. (4), (20) by the C++ library (as :func:`agvdyn.kinematics.joint_motion`)."""
    from agvdyn.platform import PAPER_PARAMETERS

    mode = Mode.from_label(mode)
    _, q_dot, q_ddot = _torques(_model(geom, PAPER_PARAMETERS, EPSILON, tolerance), extension(), mode, alpha,
                                s_dot, s_ddot, motion=True)
    return q_dot, q_ddot


def trajectory_feedforward(traj, params: Parameters | ModelParameters) -> np.ndarray:
    """Feed-forward torques ``(N, 4)`` of a :class:`agvdyn.trajectories.Trajectory`, segment by segment
    (the C++ twin of ``Trajectory.feedforward``)."""
    core = extension()
    model = _model(traj.geometry, params, EPSILON, MODE_TOLERANCE)
    return np.concatenate([_torques(model, core, s.mode, s.alpha, s.s_dot, s.s_ddot) for s in traj.segments])


def read_parameter_file(path) -> dict:
    """What the C++ reader (``agvdyn_ff::read_parameter_file``) finds in a parameter file:
    ``{"parameters": {name: value}, "platform": {name, l, b, a, r, i_G} or None, "model": {friction,
    delay_s, com_offset} or None, "extra": {name: value}}`` (the extra parameters of the model's
    extensions, :data:`agvdyn.model_spec.EXTRA_NAMES`); ValueError otherwise."""
    return extension().read_parameter_file(str(path))


# --- payload tracker ------------------------------------------------------------------------------

#: Fields of agvdyn.online.TrackerSettings that the C++ tracker takes (the rest belong to the rows).
TRACKER_SETTINGS = ("change_size", "gate", "correlation", "rotation_correlation", "threshold", "random_walk",
                    "bias_walk", "reset_std", "noise_time", "warm_rows", "initial_std", "bias_std", "twin_bias_std",
                    "noise", "com_offset", "offset_change", "offset_std", "offset_walk")


def track_rows(kind, phi, z, state, settings, nominal, dt: float):
    """The rows of one log through ``agvdyn_ff::PayloadTracker`` (the C++ twin of
    ``agvdyn.online._kernels.track_rows``): ``kind`` (N,), ``phi`` (N, 2; (N, 3) with ``settings.com_offset``),
    ``z`` (N,); ``state`` an ``agvdyn.online.tracker.TrackerState`` (updated in place), ``settings`` a
    ``TrackerSettings``, ``nominal`` (m_ch, C_ch), ``dt`` s. Returns estimates (N, ns), variances (N, ns)
    (ns = 8, 9 with the offset), NIS (N,), event flags (N,), the events as tuples (sample, start, parameter,
    sign, before, before_var, after, after_var) and (y_c, its std) (N, 2) ((N, 0) without the offset).
    ValueError naming the first refused row (unknown kind, NaN or infinity)."""
    core = extension()
    tracker = core.PayloadTracker((float(nominal[0]), float(nominal[1])), (0.0, 0.0), float(dt),
                                  {k: float(getattr(settings, k)) for k in TRACKER_SETTINGS})
    arrays = (state.theta, state.P, state.R, state.n_rows, state.g, state.Iw, state.bw, state.start)
    if not all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.flags.c_contiguous for a in arrays):
        raise ValueError("tracker state: expected C-contiguous float64 arrays (TrackerState)")
    tracker.load_state(*arrays)
    kind = np.ascontiguousarray(kind, dtype=np.int64)
    phi = np.ascontiguousarray(phi, dtype=float)
    z = np.ascontiguousarray(z, dtype=float)
    n = kind.size
    ns = tracker.states
    theta, var, nis = np.zeros((n, ns)), np.zeros((n, ns)), np.zeros(n)
    flag = np.zeros(n, dtype=np.int64)
    offset = np.zeros((n if settings.com_offset else 0, 2))
    status, row, events = tracker.run(kind, phi, z, theta, var, nis, flag, offset if settings.com_offset else None)
    tracker.store_state(*arrays)
    if row >= 0:
        raise ValueError(f"C++ tracker, row {row}: kind {int(kind[row])}, phi {phi[row].tolist()}, z {float(z[row])}: "
                         f"{core.status_name(status)}: expected a kind 0..8 and finite phi, z")
    return theta, var, nis, flag, events, offset
