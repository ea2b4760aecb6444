"""Settings of the identification and the names the stages share (paper sec. 6-7)."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from types import MappingProxyType
from typing import Any

from agvdyn.kinematics import MODE_TOLERANCE
from agvdyn.platform import EPSILON
from agvdyn.signals import FilterSettings

__all__ = [
    "DEFAULT_FIXED", "OFFSET_NAMES", "EXCITATION", "STEERING_COORDINATES", "CHASSIS_COORDINATES",
    "Filtering", "IdentificationSettings",
]

#: Parameters taken as known by default (eq. 24): B_w from a single-axis test (sec. 7).
DEFAULT_FIXED: Mapping[str, float] = MappingProxyType({"B_w": 0.121})

#: Names of the motor-torque offsets (nuisance parameters, motor side, N m).
OFFSET_NAMES = ("offset_fl", "offset_rl", "offset_fr", "offset_rr")

#: Which experiment excites each parameter (Table 1, PLATFORM.md segment names).
EXCITATION: Mapping[str, str] = MappingProxyType({
    "C_l": "steer_left (mode 1: steering the left wheel set at rest)",
    "d_vl": "steer_left (mode 1: steering the left wheel set at rest)",
    "d_cl": "steer_left (mode 1: steering the left wheel set at rest)",
    "C_r": "steer_right (mode 1: steering the right wheel set at rest)",
    "d_vr": "steer_right (mode 1: steering the right wheel set at rest)",
    "d_cr": "steer_right (mode 1: steering the right wheel set at rest)",
    "m_ch": "straight (mode 2 with alpha_v = 0) or lateral (mode 3)",
    "C_ch": "rotation (mode 4)",
    "d_vw": "straight, lateral or rotation",
    "d_cw": "straight, lateral or rotation",
    "B_w": "the lifted-wheel test (agvdyn simulate/identify lifted-wheel: wheels off the ground), then --fix "
           "B_w=VALUE; or, on the floor, fast rotation plus tight car-like turns (agvdyn simulate car-like, about "
           "2 min: B_w to ~3-4 %, as the inertia seen at the contact points)",
    **dict.fromkeys(OFFSET_NAMES, "the four identification segments together (steer_left, steer_right, straight and "
                                  "rotation each see another combination of the motor offsets), or no offset "
                                  "estimation (--no-offsets)"),
})

#: Generalized coordinates of the steering (eq. 10, 11) and of the chassis (eq. 11-13).
STEERING_COORDINATES = ("alpha_l", "alpha_r", "alpha_v")
CHASSIS_COORDINATES = ("x_ch", "y_ch", "gamma_ch")


class Filtering(str, Enum):
    """How measurement noise is filtered out of eq. (19).

    PARALLEL (default): the same zero-phase low-pass on every entry of Theta (tanh Coulomb
    terms included) and on the torques, so both sides of the equation see the same filter.
    LITERAL: the paper's wording: filtered angles and derivatives, filtered torques, tanh of
    the filtered velocity, no filtering of the regressor entries themselves.
    """

    PARALLEL = "parallel"
    LITERAL = "literal"


_NON_NEGATIVE = ("stiction_threshold", "steering_threshold", "stiction_guard", "steering_guard", "mode_tolerance",
                 "epsilon", "rank_tolerance", "sample_jitter", "rest_speed", "steering_rest_rate", "edge_guard",
                 "slip_spread", "slip_floor", "slip_guard", "slip_cutoff", "stretch_gap", "steering_jump_rate",
                 "wheel_jump_rate")


def _per_coordinate(chassis: float, steering: float) -> dict[str, float]:
    """``chassis`` for each chassis coordinate name, ``steering`` for each steering one."""
    return {**dict.fromkeys(CHASSIS_COORDINATES, chassis), **dict.fromkeys(STEERING_COORDINATES, steering)}


@dataclass(frozen=True)
class IdentificationSettings:
    """Settings of :func:`agvdyn.identification.identify` (all tuning constants in one frozen place).

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

    Rows (modes from the configuration; labels are hints)
    -----------------------------------------------------
    mode_tolerance : tolerance (rad) of the mode relations of eq. (9).
    rest_speed : a row whose wheel surface speed not explained by steering is below this (m/s)
        has the chassis at rest.
    steering_rest_rate : a steering rate above this (rad/s) with the chassis at rest is wheel
        alignment (mode 1), whatever the angles.
    segments : segment labels whose rows are used; None: every row in a motion mode.
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

    Equation rows and regression
    ----------------------------
    stiction_threshold : rows of x_ch, y_ch, gamma_ch with ``|s_dot|`` below this are dropped (sec. 7).
    steering_threshold : the same for alpha_l, alpha_r, alpha_v (rad/s); larger: the steering
        torque is dominated by Coulomb friction and stick/slip around reversals.
    stiction_guard : rows within ``stiction_guard / filter.cutoff`` s of a stiction row or a mode
        change are dropped too (the filter spreads each sample over about that time).
    steering_guard : the same for the steering coordinates (default 4: 100 ms, since stop 23). At
        a steering reversal the joint sticks against 10-20x the torque its inertia needs; that step,
        spread by the filter (its step response overshoots by 6.8 % at 3 / cutoff and stays within
        5 % from 4 / cutoff on), biased C_l and C_r with 2 by -5 to -20 % where the friction is
        large against the inertia or sticks harder than it slides; 4 costs cond (the default
        sequence 17.4 -> 20.8) and some of the steering stds (docs/identification.md, step 6).
    torque_offsets : estimate a constant offset of each motor-torque measurement (nuisance
        parameters shared by all logs of one identification).
    epsilon : width of the tanh Coulomb model, rad/s.
    torque_lead : samples (0..1) by which the logged motor torques lead the angles of their row.
        A drive that logs the torque it then holds until the next sample (zero-order hold, as
        ``agvdyn.simulation``) acts, seen from the angle samples, half a sample later: 0.5. The
        torques are moved back by linear interpolation (:func:`~.stretches.align_torque`); without
        it the regression sees the torque ``T_s / 2`` early, which biases every inertia by
        ``T_s / 2`` times its coordinate's damping (C_l +1.4 %, C_r +0.7 % at T_s = 2 ms).
        None: the log sidecar's ``torque_lead``, else 0 (torque sampled with the angles).
    rank_tolerance : relative size below which a column counts as a combination of others.
    max_inflation, max_relative_std : quality limits (variance inflation of the unit-norm
        columns; std as a fraction of the value); ``inf`` switches a check off.
    unexcited : what parameters the data do not excite (or excite only as a group, or too
        weakly) do: ``"refuse"`` the identification naming them, or ``"report"`` them with an
        unbounded 95 % interval and a warning, the rest identified. None: ``report`` for the
        estimator ``bounded``, ``refuse`` otherwise.
    plausibility : refuse negative masses, inertias and frictions, naming the likely cause.

    Estimator and uncertainty
    -------------------------
    estimator : ``ols``, ``wls``, ``robust`` or ``bounded`` (:mod:`agvdyn.identification.estimators`).
    robust_loss : ``tukey`` or ``huber`` (estimator ``robust``).
    bounds : extra bounds ``((name, low, high), ...)`` of the estimator ``bounded``.
    uncertainty : ``classic`` (eq. 25), ``hac``, ``jackknife`` (default) or ``bootstrap``
        (:mod:`agvdyn.identification.uncertainty`).
    bandwidth : HAC bandwidth / bootstrap block length / half the jackknife block in samples; None: from the data,
        ``bandwidth_factor`` times the residual scores' integrated correlation time, at least
        ``min_bandwidth``.
    bootstrap_replicates, seed : replicates and seed of the bootstrap.
    """

    filter: FilterSettings = FilterSettings()
    filtering: Filtering = Filtering.PARALLEL
    stretch_gap: float = 3.0
    steering_jump_rate: float = 20.0
    wheel_jump_rate: float = 1000.0
    edge_guard: float = 10.0
    sample_jitter: float = 0.05
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
    torque_offsets: bool = True
    epsilon: float = EPSILON
    torque_lead: float | None = None
    rank_tolerance: float = 1e-6
    max_inflation: float = 100.0
    max_relative_std: float = 0.5
    unexcited: str | None = None
    plausibility: bool = True
    estimator: str = "wls"
    robust_loss: str = "tukey"
    bounds: tuple[tuple[str, float, float], ...] = ()
    uncertainty: str = "jackknife"
    bandwidth: int | None = None
    bandwidth_factor: float = 2.0
    min_bandwidth: int = 50
    bootstrap_replicates: int = 200
    seed: int = 0

    def __post_init__(self) -> None:
        from agvdyn.identification.estimators import ESTIMATORS
        from agvdyn.identification.uncertainty import UncertaintyMethod

        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator {self.estimator!r}: expected one of {sorted(ESTIMATORS)}")
        if self.unexcited not in (None, "refuse", "report"):
            raise ValueError(f"unexcited={self.unexcited!r}: expected 'refuse' or 'report'")
        if self.robust_loss not in ("tukey", "huber"):
            raise ValueError(f"robust loss {self.robust_loss!r}: expected 'tukey' or 'huber'")
        methods = [m.value for m in UncertaintyMethod]
        if self.uncertainty not in methods:
            raise ValueError(f"uncertainty {self.uncertainty!r}: expected one of {methods}")
        if self.bandwidth is not None and not (isinstance(self.bandwidth, int) and self.bandwidth >= 1):
            raise ValueError(f"bandwidth={self.bandwidth}: expected an integer >= 1 (samples) or None")
        if not (isinstance(self.bootstrap_replicates, int) and self.bootstrap_replicates >= 20):
            raise ValueError(f"bootstrap_replicates={self.bootstrap_replicates}: expected an integer >= 20")
        object.__setattr__(self, "bounds", tuple((str(n), float(lo), float(hi)) for n, lo, hi in self.bounds))
        object.__setattr__(self, "filtering", Filtering(self.filtering))
        for key in _NON_NEGATIVE:
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"identification setting {key}={value}: expected a finite number >= 0")
        for key in ("max_inflation", "max_relative_std"):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or math.isnan(value) or value <= 0:
                raise ValueError(f"identification setting {key}={value}: expected a number > 0 (inf: no check)")
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
        if self.segments is not None:
            from agvdyn.io import SEGMENTS

            names = tuple(str(s).strip() for s in self.segments)
            unknown = [n for n in names if n not in SEGMENTS]
            if unknown:
                raise ValueError(f"unknown segment names {unknown}: expected some of {list(SEGMENTS)}")
            if not names:
                raise ValueError(f"no segment names given: expected some of {list(SEGMENTS)}")
            object.__setattr__(self, "segments", names)

    @property
    def reports_unexcited(self) -> bool:
        """Unexcited parameters get an unbounded interval instead of a refusal (see ``unexcited``)."""
        return (self.unexcited or ("report" if self.estimator == "bounded" else "refuse")) == "report"

    def thresholds(self) -> dict[str, float]:
        """Stiction threshold of each generalized coordinate name."""
        return _per_coordinate(self.stiction_threshold, self.steering_threshold)

    def guards(self) -> dict[str, float]:
        """Stiction guard (multiples of ``1 / filter.cutoff``) of each generalized coordinate name."""
        return _per_coordinate(self.stiction_guard, self.steering_guard)

    def seconds(self, multiple: float) -> float:
        """``multiple / filter.cutoff``: a time in units of the filter's time constant, s."""
        return multiple / self.filter.cutoff

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "filter_cutoff_rad_s": self.filter.cutoff,
            "filter_order": self.filter.order,
            "derivative": self.filter.derivative.value,
            "filtering": self.filtering.value,
            "segments": None if self.segments is None else list(self.segments),
            "slip_threshold": self.slip_threshold,
            "torque_offsets": self.torque_offsets,
            "torque_lead": self.torque_lead,
            "plausibility": self.plausibility,
        }
        out.update({k: getattr(self, k) for k in _NON_NEGATIVE})
        out.update(max_inflation=self.max_inflation, max_relative_std=self.max_relative_std, unexcited=self.unexcited,
                   estimator=self.estimator, robust_loss=self.robust_loss, bounds=[list(b) for b in self.bounds],
                   uncertainty=self.uncertainty, bandwidth=self.bandwidth, bandwidth_factor=self.bandwidth_factor,
                   min_bandwidth=self.min_bandwidth, bootstrap_replicates=self.bootstrap_replicates, seed=self.seed)
        return out

    def make_estimator(self):
        """The estimator these settings name."""
        from agvdyn.identification.estimators import Bounded, Robust, make_estimator

        if self.estimator == "robust":
            return Robust(loss=self.robust_loss)  # type: ignore[arg-type]
        if self.estimator == "bounded":
            return Bounded({n: (lo, hi) for n, lo, hi in self.bounds})
        return make_estimator(self.estimator)
