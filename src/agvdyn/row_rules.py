"""Which samples of a log become rows of eq. (19): the rules the identification applies and the planner predicts.

A low module (it imports :mod:`agvdyn.platform` and :mod:`agvdyn.kinematics` only), so that the planner
(:mod:`agvdyn.trajectories.planner`, below the identification) and the identification
(:mod:`agvdyn.identification`, which re-exports these names) share one definition:

* :class:`FilterSettings`: the zero-phase low-pass of every signal (sec. 7; :mod:`agvdyn.signals` filters);
* :class:`RowSettings`: filter, continuous stretches, motion modes, slip, stiction thresholds and guards,
  segments and torque timing; every guard in ONE unit, multiples of the filter's time constant
  ``1 / filter.cutoff`` (:meth:`RowSettings.guard_samples` turns one into samples);
* :func:`row_mask`: the rows of one generalized coordinate kept by the stiction threshold and its guard
  (the identification's compiled kernel computes the same mask, ``tests/test_settings_layout.py``);
  :func:`guarded_mask` its guard.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from agvdyn.kinematics import MODE_TOLERANCE
from agvdyn.platform import EPSILON

__all__ = ["DerivativeScheme", "FilterSettings", "Filtering", "RowSettings", "STEERING_COORDINATES",
           "CHASSIS_COORDINATES", "guarded_mask", "row_mask"]

#: Generalized coordinates of the steering (eq. 10, 11) and of the chassis (eq. 11-13).
STEERING_COORDINATES = ("alpha_l", "alpha_r", "alpha_v")
CHASSIS_COORDINATES = ("x_ch", "y_ch", "gamma_ch")


class DerivativeScheme(str, Enum):
    """Finite-difference scheme of :func:`time_derivative`."""

    #: second-order central differences inside, second-order one-sided at the ends (np.gradient)
    CENTRAL = "central"


@dataclass(frozen=True)
class FilterSettings:
    """Zero-phase Butterworth low-pass used for every signal (paper sec. 7).

    Parameters
    ----------
    cutoff : float
        Cut-off angular frequency ``omega_g`` in rad/s (paper: 40 rad/s).
    order : int
        Order of the Butterworth prototype; the forward-backward pass doubles it.
    derivative : DerivativeScheme
        Finite-difference scheme applied after filtering.
    """

    cutoff: float = 40.0
    order: int = 4
    derivative: DerivativeScheme = DerivativeScheme.CENTRAL

    def __post_init__(self) -> None:
        if not isinstance(self.cutoff, (int, float)) or not math.isfinite(self.cutoff) or self.cutoff <= 0:
            raise ValueError(f"filter cutoff={self.cutoff!r} rad/s: expected a finite number > 0")
        if isinstance(self.order, bool) or not isinstance(self.order, int) or not 1 <= self.order <= 12:
            raise ValueError(f"filter order={self.order!r}: expected an integer in 1..12")
        object.__setattr__(self, "cutoff", float(self.cutoff))
        object.__setattr__(self, "derivative", DerivativeScheme(self.derivative))

    def sos(self, dt: float) -> np.ndarray:
        """Second-order sections of the digital Butterworth filter for sample time ``dt`` (s)."""
        nyquist = math.pi / dt  # rad/s
        if self.cutoff >= nyquist:
            raise ValueError(
                f"filter cutoff {self.cutoff} rad/s is not below the Nyquist frequency {nyquist:.6g} rad/s "
                f"of the sample time {dt} s"
            )
        return _design(self.order, self.cutoff / nyquist)[0].copy()

    def padlen(self, dt: float) -> int:
        """Number of samples ``sosfiltfilt`` pads at each end (its default for these sections)."""
        sos = self.sos(dt)
        return 3 * (2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum()))


@functools.lru_cache(maxsize=64)
def _design(order: int, normalized_cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """Sections and ``sosfilt_zi`` of a Butterworth low-pass, designed once per order and cut-off
    (kept on disk: :mod:`agvdyn._filter_cache`)."""
    from agvdyn._filter_cache import butterworth_lowpass

    return butterworth_lowpass(order, normalized_cutoff)



def guarded_mask(keep: np.ndarray, guard: int, *, axis: int = 0) -> np.ndarray:
    """``keep`` with every row within ``guard`` samples of a dropped row (or of an end) dropped too.

    A zero-phase filter spreads each sample over about ``2 / omega_g`` on both sides, so rows next
    to the stiction rows carry what happens at low speed (stick/slip, wheel slip, the tanh
    transition) after filtering; this removes them. O(N) by cumulative sums.

    Examples
    --------
    >>> guarded_mask(np.array([True, True, True, False, True, True, True, True]), 1).tolist()
    [False, True, False, False, False, True, True, False]
    """
    keep = np.asarray(keep, dtype=bool)
    if guard < 0:
        raise ValueError(f"guard={guard!r}: expected >= 0 samples")
    if guard == 0:
        return keep.copy()
    moved = np.moveaxis(keep, axis, 0)
    n = moved.shape[0]
    bad = np.concatenate([np.ones((guard,) + moved.shape[1:], dtype=np.int64), (~moved).astype(np.int64),
                          np.ones((guard,) + moved.shape[1:], dtype=np.int64)])
    cs = np.concatenate([np.zeros((1,) + moved.shape[1:], dtype=np.int64), np.cumsum(bad, axis=0)])
    window = cs[2 * guard + 1: 2 * guard + 1 + n] - cs[:n]  # bad rows in [i - guard, i + guard]
    return np.moveaxis(window == 0, 0, axis)



def row_mask(s_dot: np.ndarray, threshold: float, guard: int, usable: np.ndarray | None = None) -> np.ndarray:
    """Rows of one generalized coordinate kept for eq. (19): ``|s_dot| >= threshold`` (sec. 7) and
    ``usable``, with every row within ``guard`` samples of a dropped row or an end dropped too
    (:func:`guarded_mask`). The planner predicts the identification's rows with it; the identification's
    compiled pass (:func:`agvdyn.identification._kernels.stretch_projection`) computes the same mask per run.

    Examples
    --------
    >>> row_mask(np.array([0.2, 0.3, 0.2, 0.0, 0.2, 0.3, 0.2, 0.2]), 0.1, 1).tolist()
    [False, True, False, False, False, True, True, False]
    """
    keep = np.abs(np.asarray(s_dot, dtype=float)) >= threshold
    if usable is not None:
        keep &= np.asarray(usable, dtype=bool)
    return guarded_mask(keep, guard)


class Filtering(str, Enum):
    """How measurement noise is filtered out of eq. (19).

    PARALLEL (default): the same zero-phase low-pass on every entry of Theta (tanh Coulomb
    terms included) and on the torques, so both sides of the equation see the same filter.
    LITERAL: the paper's wording: filtered angles and derivatives, filtered torques, tanh of
    the filtered velocity, no filtering of the regressor entries themselves.
    MATCHED: PARALLEL with the torques and the friction entries (functions of once-filtered rates)
    passed through the angles' filter first, so that every entry of both sides sees the same two
    filters (the accelerations are derivatives of filtered angles, filtered again; in PARALLEL the
    torques and the tanh entries pass one filter only), as the online tracker does
    (:mod:`agvdyn.online.rows`). The same on smooth data; at a steering breakaway the acceleration
    jumps within ~20 ms, and one filter against two leaves ``C (F a - F F a)``, several N m, on the
    rows next to every stick phase. With breakaway friction (static 1.3x sliding, 15 logs) MATCHED and
    ``steering_guard`` 12 bring the mean |error| of C_r from 11 % (largest 27 %) to 1.2 % (4.3 %) and
    of d_vr from 22 % (48 %) to 3.0 % (7.8 %) (docs/identification.md, "Breakaway friction"); the
    default stays PARALLEL.
    """

    PARALLEL = "parallel"
    LITERAL = "literal"
    MATCHED = "matched"


#: Settings of :class:`RowSettings` that are finite numbers >= 0 (in the order of ``to_dict``'s keys).
NON_NEGATIVE = ("stiction_threshold", "steering_threshold", "stiction_guard", "steering_guard", "mode_tolerance",
                "epsilon", "sample_jitter", "rest_speed", "steering_rest_rate", "edge_guard", "slip_spread",
                "slip_floor", "slip_guard", "slip_cutoff", "stretch_gap", "steering_jump_rate", "wheel_jump_rate")


def per_coordinate(chassis: float, steering: float) -> dict[str, float]:
    """``chassis`` for each chassis coordinate name, ``steering`` for each steering one."""
    return {**dict.fromkeys(CHASSIS_COORDINATES, chassis), **dict.fromkeys(STEERING_COORDINATES, steering)}


@dataclass(frozen=True)
class RowSettings:
    """Which samples of a log become rows of eq. (19) (the identification's row stage; the planner
    predicts the same rows). Every guard is a multiple of the filter's time constant ``1 / filter.cutoff``.

    Signals (one filter per continuous recording)
    ----------------------------------------------
    filter : zero-phase low-pass (cut-off 40 rad/s by default, sec. 7).
    filtering : PARALLEL (default) or LITERAL, see :class:`Filtering`.
    stretch_gap : a time step longer than this many nominal steps splits a log into two
        continuous stretches (a dropout), each filtered on its own.
    steering_jump_rate, wheel_jump_rate : an angle step faster than this (rad/s) between two
        samples is a discontinuity (two recordings joined, an encoder reset): split there too.
    edge_guard : rows within ``edge_guard / filter.cutoff`` s of a stretch's ends are dropped
        (the start and end transients of the zero-phase filter and of the derivatives of its
        odd-extended ends; 10 / 40 rad/s = 250 ms).
    sample_jitter : largest relative deviation of a time step from the median inside a stretch.
    epsilon : width of the tanh Coulomb model, rad/s.
    torque_lead : samples (0..1) by which the logged motor torques lead the angles of their row.
        A drive that logs the torque it then holds until the next sample (zero-order hold, as
        ``agvdyn.simulation``) acts, seen from the angle samples, half a sample later: 0.5. The
        torques are moved back by linear interpolation (``identification.stretches.align_torque``);
        without it the regression sees the torque ``T_s / 2`` early, which biases every inertia by
        ``T_s / 2`` times its coordinate's damping (C_l +1.4 %, C_r +0.7 % at T_s = 2 ms).
        None: the log sidecar's ``torque_lead``, else 0 (torque sampled with the angles).

    Modes (from the configuration; labels are hints)
    ------------------------------------------------
    mode_tolerance : tolerance (rad) of the mode relations of eq. (9).
    rest_speed : a row whose wheel surface speed not explained by steering is below this (m/s)
        has the chassis at rest.
    steering_rest_rate : a steering rate above this (rad/s) with the chassis at rest is wheel
        alignment (mode 1), whatever the angles.
    segments : segment labels whose rows are used; None: every row in a motion mode (the names are
        checked against the log schema's by :class:`agvdyn.identification.IdentificationSettings`).

    Slip
    ----
    slip_threshold : slip speed (m/s) above which a row is wheel slip; None: from the robust
        spread of the log's slip speed, ``median + slip_spread * 1.4826 MAD``, at least
        ``slip_floor``. ``inf`` switches slip detection off. The slip speed of a row is each
        wheel's own (one wheel left out, :func:`agvdyn.odometry.odometry_with_slip`); a tyre
        creeps by up to ~0.02 m/s right after a disturbance, hence the floor of 0.025 m/s.
    slip_guard : rows within this time (s) of a slip row are dropped too.
    slip_cutoff : cut-off (rad/s) of the zero-phase low-pass of the steering angles whose rates
        enter the slip speed (at most 0.8 x Nyquist); the wheel angles enter unfiltered. Far
        above ``filter.cutoff``: a slip of 20 ms would be smeared over 0.2 s and shrunk by the
        regression's filter.

    Stiction (sec. 7)
    -----------------
    stiction_threshold : rows of x_ch, y_ch, gamma_ch with ``|s_dot|`` below this are dropped (m/s, rad/s).
    steering_threshold : the same for alpha_l, alpha_r, alpha_v (rad/s); larger: the steering
        torque is dominated by Coulomb friction and stick/slip around reversals.
    stiction_guard : rows within ``stiction_guard / filter.cutoff`` s of a stiction row or a mode
        change are dropped too (the filter spreads each sample over about that time; 2: 50 ms).
    steering_guard : the same for the steering coordinates (default 4: 100 ms, since stop 23). At
        a steering reversal the joint sticks against 10-20x the torque its inertia needs; that step,
        spread by the filter (its step response overshoots by 6.8 % at 3 / cutoff and stays within
        5 % from 4 / cutoff on), biased C_l and C_r with 2 by -5 to -20 % where the friction is
        large against the inertia or sticks harder than it slides; 4 costs cond (the default
        sequence 17.4 -> 20.8) and some of the steering stds (docs/identification.md, step 6).
    """

    filter: FilterSettings = FilterSettings()
    filtering: Filtering = Filtering.PARALLEL
    stretch_gap: float = 3.0
    steering_jump_rate: float = 20.0
    wheel_jump_rate: float = 1000.0
    edge_guard: float = 10.0
    sample_jitter: float = 0.05
    epsilon: float = EPSILON
    torque_lead: float | None = None
    mode_tolerance: float = MODE_TOLERANCE
    rest_speed: float = 0.01
    steering_rest_rate: float = 0.02
    segments: tuple[str, ...] | None = None
    slip_threshold: float | None = None
    slip_spread: float = 10.0
    slip_floor: float = 0.025
    slip_guard: float = 0.1
    slip_cutoff: float = 250.0
    stiction_threshold: float = 0.05
    steering_threshold: float = 0.1
    stiction_guard: float = 2.0
    steering_guard: float = 4.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "filtering", Filtering(self.filtering))
        for key in NON_NEGATIVE:
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"identification setting {key}={value}: expected a finite number >= 0")
        if self.slip_threshold is not None and not (isinstance(self.slip_threshold, (int, float))
                                                    and self.slip_threshold > 0):
            raise ValueError(f"identification setting slip_threshold={self.slip_threshold}: expected a number "
                             "> 0 in m/s (inf: no slip detection), or None (from the data)")
        if self.torque_lead is not None and not (isinstance(self.torque_lead, (int, float))
                                                 and not isinstance(self.torque_lead, bool)
                                                 and 0 <= self.torque_lead <= 1):
            raise ValueError(f"identification setting torque_lead={self.torque_lead!r}: expected a number of "
                             "samples in [0, 1] (0.5: zero-order-hold drive), or None (from the log's sidecar)")
        if self.epsilon <= 0 or self.mode_tolerance <= 0 or self.stretch_gap < 1:
            raise ValueError("identification settings: epsilon and mode_tolerance must be > 0, stretch_gap >= 1")
        if self.segments is not None:  # the names are checked by IdentificationSettings (the log schema's)
            object.__setattr__(self, "segments", tuple(str(s).strip() for s in self.segments))

    def thresholds(self) -> dict[str, float]:
        """Stiction threshold of each generalized coordinate name."""
        return per_coordinate(self.stiction_threshold, self.steering_threshold)

    def guards(self) -> dict[str, float]:
        """Stiction guard (multiples of ``1 / filter.cutoff``) of each generalized coordinate name."""
        return per_coordinate(self.stiction_guard, self.steering_guard)

    def threshold(self, coordinate: str) -> float:
        """Stiction threshold of one generalized coordinate name."""
        return self.thresholds()[coordinate]

    def seconds(self, multiple: float) -> float:
        """``multiple / filter.cutoff``: a time in units of the filter's time constant, s."""
        return multiple / self.filter.cutoff

    def guard_samples(self, multiple: float, dt: float) -> int:
        """A guard of ``multiple / filter.cutoff`` s in samples of ``dt`` s (rounded)."""
        return int(round(self.seconds(multiple) / dt))
