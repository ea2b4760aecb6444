"""Settings of the identification's fit and uncertainty stages, and the choices they take (enums).

The row stage's settings are :class:`agvdyn.row_rules.RowSettings` (shared with the planner);
:class:`agvdyn.identification.IdentificationSettings` holds one of each stage.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

__all__ = ["EstimatorName", "RobustLoss", "Unexcited", "UncertaintyMethod", "FitSettings", "UncertaintySettings"]


class EstimatorName(str, Enum):
    """The estimators of :mod:`agvdyn.identification.estimators` (``identify --estimator``)."""

    OLS = "ols"
    WLS = "wls"
    ROBUST = "robust"
    BOUNDED = "bounded"


class RobustLoss(str, Enum):
    """Loss of the estimator ``robust`` (IRLS)."""

    TUKEY = "tukey"
    HUBER = "huber"


class Unexcited(str, Enum):
    """What parameters the data do not excite do (``identify --unexcited``)."""

    REFUSE = "refuse"
    REPORT = "report"


class UncertaintyMethod(str, Enum):
    """``identify --uncertainty`` (:mod:`agvdyn.identification.uncertainty`)."""

    CLASSIC = "classic"
    HAC = "hac"
    JACKKNIFE = "jackknife"
    BOOTSTRAP = "bootstrap"


def _choice(kind: type[Enum], value: object, what: str, expected: str) -> Enum:
    try:
        return kind(value)
    except ValueError:
        raise ValueError(f"{what} {value!r}: expected {expected}") from None


@dataclass(frozen=True)
class FitSettings:
    """The regression stage: columns, estimator, rank and quality checks, plausibility (eq. 22-25).

    torque_offsets : estimate a constant offset of each motor-torque measurement (nuisance
        parameters shared by all logs of one identification).
    estimator : :class:`EstimatorName` (:mod:`agvdyn.identification.estimators`).
    robust_loss : :class:`RobustLoss` of the estimator ``robust``.
    bounds : extra bounds ``((name, low, high), ...)`` of the estimator ``bounded``.
    rank_tolerance : relative size below which a column counts as a combination of others.
    max_inflation, max_relative_std : quality limits (variance inflation of the unit-norm
        columns; std as a fraction of the value); ``inf`` switches a check off.
    unexcited : what parameters the data do not excite (or excite only as a group, or too
        weakly) do: ``refuse`` the identification naming them, or ``report`` them with an
        unbounded 95 % interval and a warning, the rest identified. None: ``report`` for the
        estimator ``bounded``, ``refuse`` otherwise.
    plausibility : refuse negative masses, inertias and frictions, naming the likely cause.
    """

    torque_offsets: bool = True
    estimator: EstimatorName = EstimatorName.WLS
    robust_loss: RobustLoss = RobustLoss.TUKEY
    bounds: tuple[tuple[str, float, float], ...] = ()
    rank_tolerance: float = 1e-6
    max_inflation: float = 100.0
    max_relative_std: float = 0.5
    unexcited: Unexcited | None = None
    plausibility: bool = True

    def __post_init__(self) -> None:
        names = sorted(e.value for e in EstimatorName)
        object.__setattr__(self, "estimator", _choice(EstimatorName, self.estimator, "estimator",
                                                      f"one of {names}"))
        if self.unexcited is not None:
            try:
                object.__setattr__(self, "unexcited", Unexcited(self.unexcited))
            except ValueError:
                raise ValueError(f"unexcited={self.unexcited!r}: expected 'refuse' or 'report'") from None
        object.__setattr__(self, "robust_loss", _choice(RobustLoss, self.robust_loss, "robust loss",
                                                        "'tukey' or 'huber'"))
        object.__setattr__(self, "bounds", tuple((str(n), float(lo), float(hi)) for n, lo, hi in self.bounds))
        value = self.rank_tolerance
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise ValueError(f"identification setting rank_tolerance={value}: expected a finite number >= 0")
        for key in ("max_inflation", "max_relative_std"):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or math.isnan(value) or value <= 0:
                raise ValueError(f"identification setting {key}={value}: expected a number > 0 (inf: no check)")

    @property
    def reports_unexcited(self) -> bool:
        """Unexcited parameters get an unbounded interval instead of a refusal (see ``unexcited``)."""
        if self.unexcited is not None:
            return self.unexcited is Unexcited.REPORT
        return self.estimator is EstimatorName.BOUNDED

    def make_estimator(self):
        """The estimator these settings name."""
        from agvdyn.identification.estimators import Bounded, Robust, make_estimator

        if self.estimator is EstimatorName.ROBUST:
            return Robust(loss=self.robust_loss.value)  # type: ignore[arg-type]
        if self.estimator is EstimatorName.BOUNDED:
            return Bounded({n: (lo, hi) for n, lo, hi in self.bounds})
        return make_estimator(self.estimator.value)


@dataclass(frozen=True)
class UncertaintySettings:
    """The uncertainty stage (:mod:`agvdyn.identification.uncertainty`).

    method : :class:`UncertaintyMethod`: ``classic`` (eq. 25), ``hac``, ``jackknife`` (default) or ``bootstrap``.
    bandwidth : HAC bandwidth / bootstrap block length / half the jackknife block in samples; None: from
        the data, ``bandwidth_factor`` times the residual scores' integrated correlation time, at least
        ``min_bandwidth``.
    bootstrap_replicates, seed : replicates and seed of the bootstrap.
    """

    method: UncertaintyMethod = UncertaintyMethod.JACKKNIFE
    bandwidth: int | None = None
    bandwidth_factor: float = 2.0
    min_bandwidth: int = 50
    bootstrap_replicates: int = 200
    seed: int = 0

    def __post_init__(self) -> None:
        methods = [m.value for m in UncertaintyMethod]
        object.__setattr__(self, "method", _choice(UncertaintyMethod, self.method, "uncertainty",
                                                   f"one of {methods}"))
        if self.bandwidth is not None and not (isinstance(self.bandwidth, int) and self.bandwidth >= 1):
            raise ValueError(f"bandwidth={self.bandwidth}: expected an integer >= 1 (samples) or None")
        if not (isinstance(self.bootstrap_replicates, int) and self.bootstrap_replicates >= 20):
            raise ValueError(f"bootstrap_replicates={self.bootstrap_replicates}: expected an integer >= 20")
