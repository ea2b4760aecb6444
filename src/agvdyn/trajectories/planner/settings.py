"""Objectives, noise levels and settings of the planner, floor parsing."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from agvdyn.kinematics import Mode
from agvdyn.platform import PARAMETER_NAMES
from agvdyn.row_rules import RowSettings
from agvdyn.segments_vocabulary import IDENTIFICATION_SEGMENTS, segment_mode
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.limits import FloorSpace

if TYPE_CHECKING:
    pass


#: Objectives of :func:`plan`.
OBJECTIVES = ("std", "d-optimal", "cond")
Objective = Literal["std", "d-optimal", "cond"]

#: The four phases of sec. 6.2 in their execution order: (name, mode)
#: (:data:`agvdyn.segments_vocabulary.IDENTIFICATION_SEGMENTS`).
PHASES: tuple[tuple[str, Mode], ...] = tuple((name, Mode.from_label(segment_mode(name)))
                                             for name in IDENTIFICATION_SEGMENTS)
#: The ten parameters the sequence identifies (B_w is known, sec. 6.3).
FREE = PARAMETER_NAMES[:10]
_OFFSETS = 4


@dataclass(frozen=True)
class NoiseLevels:
    """Effective noise of one row of eq. (19) (2 ms rows) per generalized coordinate: N m for the
    steering and the yaw, N for x_ch and y_ch, and how it grows with the acceleration.

    The effective variance of a row is ``level^2 (1 + g / (1 + g / saturation))``,
    ``g = (a / knee)^4``, with the row's acceleration ``a`` of its coordinate (rad/s^2, m/s^2;
    ``knee`` inf: constant): it grows as ``a^4`` from the knee on, at most ``1 + saturation``
    times. "Effective" is the residual variance times its correlation time: the residuals are
    correlated over tens to hundreds of samples, and their long-run variance is what the std sees.
    The growth is the model error of the plant, not sensor noise: the tyres slip and twist in
    proportion to the force they transmit, so the odometry (wheel angles) sees the motion off by
    a share that grows with the acceleration, and the torque error with its square.

    Calibrated (``docs/planning.md``, "Noise levels") against the delete-one-block jackknife std of
    ``agvdyn identify`` (its default) on the simulator's default plant, seeds 1-6, on the default
    sequence and five plans of the four phases (peaks up to 13 rad/s^2 steering, 0.6 m/s^2,
    2.2 rad/s^2 yaw): predicted / jackknife 0.74-1.33. Outside that (car-like turns, mode 2/3
    rows, faster motion) the growth is extrapolated: for the car-like experiment it predicts a
    B_w std of 15 % where the default plant gives 4.5-11 % (:meth:`constant`: 2.5 %, the model
    plant 3.2-4.4 %). The identification uses the levels alone as nominal noise
    (``predicted_relative_std``). Only their ratios matter for the plan. These class defaults were
    fitted with the identification's steering guard of 2 and are the optimiser's
    (``PlanSettings.weights_noise``); the predictions use :meth:`calibrated`, fitted with 4.
    """

    alpha_l: float = 0.54
    alpha_r: float = 0.76
    alpha_v: float = 0.76
    x_ch: float = 10.1
    y_ch: float = 10.1
    gamma_ch: float = 8.95
    knee_alpha_l: float = 13.4
    knee_alpha_r: float = 5.9
    knee_alpha_v: float = 5.9
    knee_x_ch: float = 0.314
    knee_y_ch: float = 0.314
    knee_gamma_ch: float = 0.67
    saturation: float = 100.0

    def __post_init__(self) -> None:
        for key, value in self.__dict__.items():
            knee = key.startswith("knee_") or key == "saturation"
            if not (isinstance(value, (int, float)) and not math.isnan(value) and value > 0
                    and (knee or math.isfinite(value))):
                raise TrajectoryError(f"noise level {key}={value!r}: expected a finite number > 0"
                                      + (" (or inf)" if knee else ""))

    @classmethod
    def constant(cls) -> "NoiseLevels":
        """The same levels without growth: rows of equal variance per coordinate (a plant the model
        describes, e.g. ``--ideal-plant``, or motion outside the calibration: see the class)."""
        inf = math.inf
        return cls(knee_alpha_l=inf, knee_alpha_r=inf, knee_alpha_v=inf, knee_x_ch=inf, knee_y_ch=inf,
                   knee_gamma_ch=inf)

    @classmethod
    def calibrated(cls) -> "NoiseLevels":
        """The levels refitted for the identification's steering guard of 4 (since stop 23): steering
        0.359 / 0.396 N m and one knee of 8.92 rad/s^2 (the rest as the class defaults). The knee and
        the stop-24 levels 0.381 / 0.505 were fitted to the jackknife stds of 146 sequences (two
        vehicles, seeds 0-3; RMS log(predicted / jackknife) over the ten stds 0.368 -> 0.193,
        docs/planning.md, "Stop 24"); stop 30 rescaled the two levels after the plant's slow joints
        stopped sticking above their level (benchmarks/calibrate_steering_noise.py, prototype, the
        default sequence and two plans, seeds 0-3: RMS log 0.171 -> 0.102). :func:`evaluate_sequence`
        predicts with them (``PlanSettings.noise``); the optimiser keeps the class defaults
        (``PlanSettings.weights_noise``), with which its plans were better."""
        return cls(alpha_l=0.359, alpha_r=0.396, knee_alpha_l=8.92, knee_alpha_r=8.92)

    def of(self, coordinate: str) -> float:
        return float(getattr(self, coordinate))

    def knee(self, coordinate: str) -> float:
        """Acceleration at which the row's effective variance has doubled (inf: constant)."""
        return float(getattr(self, f"knee_{coordinate}"))

    def growth(self, coordinate: str) -> float:
        """``level / knee^2``: the effective noise is ``sqrt(level^2 + (growth a^2)^2)`` (N m or N per
        (unit/s^2)^2; 0 for a constant level)."""
        knee = self.knee(coordinate)
        return 0.0 if math.isinf(knee) else self.of(coordinate) / knee**2

    def variance_factor(self, coordinate: str, a: np.ndarray) -> np.ndarray:
        """The row's effective variance over ``level^2`` (see the class)."""
        knee = self.knee(coordinate)
        a = np.asarray(a, dtype=float)
        if math.isinf(knee):
            return np.ones_like(a)
        g = (a / knee) ** 4
        return 1 + g / (1 + g / self.saturation)


@dataclass(frozen=True)
class PlanSettings:
    """Settings of :func:`plan` (all tuning constants in one frozen place).

    objective : ``std`` (default), ``d-optimal`` or ``cond`` (see the module docstring).
    starts : random starts of the optimiser; ``seed`` their generator; ``workers`` processes
        (None: up to two, one per core).
    periods : repetitions of each phase's period (steer left, steer right, straight, rotation; the
        harmonics are then p, 2p, ...); default one each (docs/planning.md: a repeated straight
        took its time from the other phases and was worse on the simulator).
    harmonics : (fewest, most) harmonics of a phase; each start draws them per phase, capped so
        that the highest harmonic stays below ``max_frequency`` (rad/s, well inside the
        identification filter's 40 rad/s).
    min_phase : shortest phase, s.
    steering_excursion : largest |alpha| of the steering phases, rad (stops at pi/2).
    max_heading : largest |gamma_ch| of the rotation, rad.
    max_speed : largest chassis speed of the straight motion, m/s (below ``Limits.speed``): faster,
        tyre scrub and slip put slowly varying errors into the straight's rows (on the simulator the
        HAC std of m_ch grew 1.5x at 1.4 m/s although the prediction fell).
    max_acceleration : largest chassis acceleration of the straight motion, m/s^2 (below
        ``Limits.acceleration``), for the same reason (tyre slip grows with the force).
    reference_margin : the ``std`` objective penalises a predicted std above ``reference_margin``
        times the default sequence's: room for the prediction's errors (15-20 %) and the scatter
        of a single run's jackknife std (8-16 %), so that single runs beat the default too.
        ``parameter_margins`` overrides it by name: the stds that rest on few jackknife blocks
        (m_ch, C_ch, d_vw) or whose default-sequence prediction is high (d_cw) scatter most
        against the default's and get 0.45-0.5.
    rows : the identification's row rules (:class:`agvdyn.row_rules.RowSettings`, the same object as
        ``IdentificationSettings.rows``): its stiction thresholds (rad/s steering; m/s, rad/s chassis)
        and guards (multiples of ``1 / filter.cutoff``: 2 / 40 rad/s = 0.05 s chassis, 4 / 40 rad/s =
        0.1 s steering) predict which rows it keeps in the exact evaluation (``evaluate_sequence``:
        cond and stds), with the same mask (:func:`agvdyn.row_rules.row_mask`).
    steering_weights_guard : the steering guard the optimiser's smooth row weights assume, in the unit
        of ``rows``' guards: 2 (0.05 s at 40 rad/s), shorter than the identification's 4, so its reversal
        model counts the rows 50-100 ms after a reversal as contaminated and avoids them; with 0.1 s its
        plans were worse on the prototype (docs/planning.md, "Stop 23: a longer guard").
    validity : rows count in the objective from ``validity`` times the threshold on (smooth step
        of relative width ``validity_width``): slow motion is where the friction model is least true.
    band_penalty : weight of the share of the phases' time spent below that speed.
    reversal_window, reversal_penalty : rows within ``reversal_window`` s of a velocity reversal
        that the identification keeps carry the reversal's stick/slip, spread by its zero-phase
        filter (on the simulator they biased C_l, C_r by -3 to -11 %); they earn no credit and
        their share of the time costs ``reversal_penalty`` (see :func:`_row_weights`).
    cond_target, reference_penalty : the ``std`` objective's penalties (see the module docstring),
        ``reference_penalty`` the weight of both. ``cond_target`` 5 (6 until stop 23): with the steering
        guard of 4 the slow rows it asks for no longer bias C_l, C_r, and on four vehicles (one held out) the
        plans met the bars better (docs/planning.md, "Stop 24").
    margin : share of every limit the plan may use (the rest for tracking and rounding).
    peak_exponent : the optimiser scales each phase to the ``peak_exponent``-norm of its samples'
        ``|x| / limit`` (64, the default: a smooth bound a few per cent above the largest) or, inf,
        to the largest itself, whose kinks where two peaks are equal stop L-BFGS-B after 16-240
        iterations; the plan is scaled exactly either way. Alone, 64 gave worse plans on the simulator
        (docs/planning.md, "Stop 20"); with twelve starts and the check of ``agvdyn plan`` better ones
        on three vehicles ("Stop 23"): the defaults are the ``wide`` search of :data:`SEARCHES`.
    pause, align_rate, align_acceleration : the alignments at rest between the phases.
    grid : time step of the optimiser's evaluation, s (the result is evaluated at ``T_s``).
    max_iterations : of L-BFGS-B per start; with ``explore_iterations`` below it, every start runs
        that many and only the ``refine`` starts with the best objective go on to ``max_iterations``
        (with ``peak_exponent`` 64: 26 s instead of 61 s for six starts, the same best start).
    candidates : how many of the starts, best predicted objective first, :func:`plan` builds and
        evaluates exactly (:attr:`Plan.candidates`, about 0.3 s each) for a check on the simulator
        (:func:`agvdyn.plan_check.verify_plan`, ``agvdyn plan --verify``); 1: the best alone.
    noise : :class:`NoiseLevels` of the exact evaluation (the predicted cond is independent of them, the
        predicted stds are not): :meth:`NoiseLevels.calibrated`, fitted with the identification's guards.
    weights_noise : the levels of the optimiser's objective, the class defaults (fitted with the steering
        guard of 2): with the calibrated ones the plans were worse on three vehicles and three plants; the
        defaults' steeper cost of fast steering keeps the plans from the reversals that hurt on other
        plants (docs/planning.md, "Stop 24").
    torque_offsets : the identification estimates motor-torque offsets.
    """

    objective: str = "std"
    starts: int = 12
    seed: int = 0
    workers: int | None = None
    harmonics: tuple[int, int] = (4, 30)
    periods: tuple[int, int, int, int] = (1, 1, 1, 1)
    max_frequency: float = 10.0
    min_phase: float = 6.0
    steering_excursion: float = 1.2
    max_heading: float = math.pi
    max_speed: float = 0.8
    max_acceleration: float = 0.6
    reference_margin: float = 0.6
    parameter_margins: tuple[tuple[str, float], ...] = (("m_ch", 0.45), ("C_ch", 0.5), ("d_vw", 0.5), ("d_cw", 0.5))
    rows: RowSettings = RowSettings()
    steering_weights_guard: float = 2.0
    validity: float = 2.0
    validity_width: float = 0.15
    band_penalty: float = 0.5
    reversal_window: float = 0.25
    reversal_penalty: float = 10.0
    cond_target: float = 5.0
    reference_penalty: float = 20.0
    margin: float = 0.97
    peak_exponent: float = 64.0
    pause: float = 0.5
    align_rate: float = 0.8
    align_acceleration: float = 2.0
    grid: float = 0.02
    max_iterations: int = 300
    explore_iterations: int = 80
    refine: int = 4
    candidates: int = 1
    noise: NoiseLevels = field(default_factory=NoiseLevels.calibrated)
    weights_noise: NoiseLevels = field(default_factory=NoiseLevels)
    torque_offsets: bool = True

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise TrajectoryError(f"objective {self.objective!r}: expected one of {list(OBJECTIVES)}")
        if not (isinstance(self.starts, int) and self.starts >= 1):
            raise TrajectoryError(f"starts={self.starts!r}: expected an integer >= 1")
        lo, hi = self.harmonics
        if not (isinstance(lo, int) and isinstance(hi, int) and 2 <= lo <= hi):
            raise TrajectoryError(f"harmonics={self.harmonics!r}: expected two integers 2 <= fewest <= most")
        for key in ("max_frequency", "min_phase", "steering_excursion", "max_heading", "max_speed", "max_acceleration",
                    "reference_margin", "validity", "validity_width", "cond_target", "margin", "align_rate",
                    "align_acceleration", "grid"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise TrajectoryError(f"plan setting {key}={value!r}: expected a finite number > 0")
        if not isinstance(self.rows, RowSettings):
            raise TrajectoryError(f"rows={self.rows!r}: expected the identification's RowSettings")
        for key in ("stiction_threshold", "steering_threshold"):
            if not getattr(self.rows, key) > 0:
                raise TrajectoryError(f"plan setting rows.{key}={getattr(self.rows, key)!r}: expected a number > 0")
        for key in ("steering_weights_guard", "pause", "reference_penalty",
                    "band_penalty", "reversal_window", "reversal_penalty"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise TrajectoryError(f"plan setting {key}={value!r}: expected a finite number >= 0")
        if not (isinstance(self.peak_exponent, (int, float)) and self.peak_exponent >= 2):
            raise TrajectoryError(f"peak_exponent={self.peak_exponent!r}: expected a number >= 2 (or inf)")
        if self.margin > 1:
            raise TrajectoryError(f"margin={self.margin!r}: expected a share of the limits in (0, 1]")
        if self.steering_excursion >= math.pi / 2:
            raise TrajectoryError(f"steering_excursion={self.steering_excursion!r}: expected < pi/2 (the stops)")
        if not (len(self.periods) == len(PHASES) and all(isinstance(p, int) and p >= 1 for p in self.periods)):
            raise TrajectoryError(f"periods={self.periods!r}: expected {len(PHASES)} integers >= 1 (one per phase)")
        for key in ("max_iterations", "explore_iterations", "refine", "candidates"):
            value = getattr(self, key)
            if not (isinstance(value, int) and value >= 1):
                raise TrajectoryError(f"plan setting {key}={value!r}: expected an integer >= 1")
        if self.workers is not None and not (isinstance(self.workers, int) and self.workers >= 1):
            raise TrajectoryError(f"workers={self.workers!r}: expected an integer >= 1 or None")

    @classmethod
    def search(cls, name: str, **changes) -> "PlanSettings":
        """The settings with the optimiser's search ``name`` of :data:`SEARCHES` (``agvdyn plan --search``),
        then ``changes``."""
        try:
            preset = SEARCHES[name]
        except KeyError:
            raise TrajectoryError(f"search {name!r}: expected one of {list(SEARCHES)}") from None
        return cls(**{**preset, **changes})

    def margins(self) -> np.ndarray:
        """``reference_margin`` of each of the ten parameters (``parameter_margins`` override it by name)."""
        out = np.full(len(FREE), float(self.reference_margin))
        for name, value in self.parameter_margins:
            out[FREE.index(name)] = float(value)
        return out

    def levels(self, weights: bool = False) -> NoiseLevels:
        """The noise levels of the exact evaluation (``weights``: of the optimiser's objective)."""
        return self.weights_noise if weights else self.noise

    def threshold(self, coordinate: str) -> float:
        """The identification's stiction threshold of ``coordinate`` (``rows``)."""
        return self.rows.threshold(coordinate)

    def _guard_multiple(self, coordinate: str, weights: bool) -> float:
        if weights and coordinate.startswith("alpha"):
            return self.steering_weights_guard
        return self.rows.guards()[coordinate]

    def guard(self, coordinate: str, weights: bool = False) -> float:
        """The identification's stiction guard of ``coordinate``, s (``weights``: the one the optimiser's
        row weights assume)."""
        return self.rows.seconds(self._guard_multiple(coordinate, weights))

    def guard_samples(self, coordinate: str, dt: float) -> int:
        """The identification's stiction guard of ``coordinate`` in samples of ``dt`` s (as its rows')."""
        return self.rows.guard_samples(self._guard_multiple(coordinate, False), dt)


#: Searches of the optimiser (:meth:`PlanSettings.search`, ``agvdyn plan --search``). ``wide``: the
#: defaults of :class:`PlanSettings`, twelve starts, each phase scaled to the 64-norm of its peaks (a
#: smooth bound, so L-BFGS-B does not stop at the kinks of the max), 80 iterations each and the best
#: four on to 300. ``narrow``: six starts of 300 iterations, each phase scaled to its largest peak (the
#: default until stop 22). With the check of ``agvdyn plan``, ``wide`` was better on average over plan
#: seeds 0-5 on each of three vehicles, the third held out (docs/planning.md, "Stop 22, second helper",
#: "Stop 23").
SEARCHES: dict[str, dict[str, float | int]] = {
    "narrow": {"starts": 6, "peak_exponent": math.inf, "explore_iterations": 300, "refine": 2},
    "wide": {"starts": 12, "peak_exponent": 64.0, "explore_iterations": 80, "refine": 4},
}


def parse_floor(text: str) -> FloorSpace:
    """``"5.2x1.6"`` (metres, length along the straight motion x width) as a :class:`FloorSpace`."""
    parts = str(text).lower().replace("*", "x").replace(" ", "").split("x")
    try:
        length, width = (float(p) for p in parts)
    except ValueError:
        raise TrajectoryError(f"floor {text!r}: expected LENGTHxWIDTH in metres, e.g. 5.2x1.6") from None
    if not (math.isfinite(length) and math.isfinite(width) and length > 0 and width > 0):
        raise TrajectoryError(f"floor {text!r}: expected a length and a width > 0 m")
    return FloorSpace(length, width)


# --- the linear structure of a phase ---------------------------------------------------------------
