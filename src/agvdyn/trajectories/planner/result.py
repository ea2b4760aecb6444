"""The planner's result: the planned phases, the candidate starts kept for a check on the simulator,
and :class:`Plan` (its files and JSON); :func:`combine` pools the candidates of two searches."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from agvdyn.kinematics import Mode, nominal_steering
from agvdyn.platform import Parameters
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.limits import FloorSpace, Limits
from agvdyn.trajectories.segments import Trajectory
from agvdyn.trajectories.planner.evaluation import SequenceEvaluation
from agvdyn.trajectories.planner.settings import PlanSettings

__all__ = ["PhaseDesign", "Candidate", "Plan", "combine", "COND_BAR", "COND_SHARE"]


@dataclass(frozen=True)
class PhaseDesign:
    """One planned phase: its Fourier series (one period, at rest at both ends) and peaks."""

    name: str
    mode: str
    coordinate: str
    duration: float
    harmonics: int
    series: FourierSeries
    peak_position: float
    peak_velocity: float
    peak_acceleration: float
    limiting: str

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "mode": self.mode, "coordinate": self.coordinate, "duration": self.duration,
                "harmonics": self.harmonics, "peak_position": self.peak_position,
                "peak_velocity": self.peak_velocity, "peak_acceleration": self.peak_acceleration,
                "limiting": self.limiting, "fourier": self.series.to_dict()}


@dataclass(frozen=True, eq=False)
class Candidate:
    """One start's plan, built and evaluated exactly (:attr:`Plan.candidates`): ``rank`` 0 is the
    start with the best predicted objective."""

    start: int
    rank: int
    objective_value: float
    trajectory: Trajectory
    phases: tuple[PhaseDesign, ...]
    evaluation: SequenceEvaluation
    search: str = ""


#: What a plan should reach (issue 11): cond(Theta_1w^T Theta_1w) at most 9 and at most 0.6x the
#: default sequence's in the same floor and duration; :attr:`Plan.warnings` names a miss.
COND_BAR = 9.0
COND_SHARE = 0.6


@dataclass(frozen=True, eq=False)
class Plan:
    """Result of :func:`plan`: the planned sequence and its predicted quality next to the default
    sequence in the same floor and duration (``reference``)."""

    trajectory: Trajectory
    phases: tuple[PhaseDesign, ...]
    floor: FloorSpace
    evaluation: SequenceEvaluation
    reference: SequenceEvaluation
    reference_trajectory: Trajectory
    objective: str
    objective_value: float
    starts: tuple[dict[str, Any], ...]
    elapsed: float
    params: Parameters
    settings: PlanSettings
    limits: Limits
    candidates: tuple[Candidate, ...] = ()
    chosen: int = 0

    @property
    def cond(self) -> float:
        return self.evaluation.cond

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the plan's prediction misses: cond above :data:`COND_BAR` or above
        :data:`COND_SHARE` of the default sequence's, a predicted std above the default's. The
        identified cond follows the predicted one closely (7.78 against 7.76 on the prototype),
        the stds scatter by 15-25 % per run (docs/planning.md)."""
        ev, ref = self.evaluation, self.reference
        out = []
        if ev.cond > COND_BAR or ev.cond > COND_SHARE * ref.cond:
            out.append(f"predicted cond {ev.cond:.2f} is above {COND_BAR:g} or {COND_SHARE:g}x the default sequence's "
                       f"{ref.cond:.2f}: plan again with another --seed, more --starts or a longer --duration")
        worse = [n for n in ev.std if n in ref.std and ev.std[n] > ref.std[n]]
        if worse:
            out.append(f"predicted std of {', '.join(worse)} above the default sequence's: check the plan on the "
                       "vehicle or simulator before use, or plan with another --seed or more --starts")
        return tuple(out)

    def choose(self, rank: int) -> "Plan":
        """The same plan with the candidate of ``rank`` (its index in :attr:`candidates`) as the plan,
        e.g. the one a check on the simulator prefers (:func:`agvdyn.plan_check.verify_plan`)."""
        if not 0 <= rank < len(self.candidates):
            raise IndexError(f"candidate {rank}: the plan keeps {len(self.candidates)} (PlanSettings.candidates)")
        c = self.candidates[rank]
        return replace(self, trajectory=c.trajectory, phases=c.phases, evaluation=c.evaluation,
                       objective_value=c.objective_value, chosen=rank)

    def to_dict(self) -> dict[str, Any]:
        """Summary (``agvdyn plan --json``)."""
        ev = self.evaluation.to_dict()
        return {
            "objective": self.objective,
            "objective_value": self.objective_value,
            "cond": ev["cond"],
            "floor": {"length": self.floor.length, "width": self.floor.width},
            "floor_used": ev["floor"],
            "duration": ev["duration"],
            "peak_torque": ev["peak_torque"],
            "std": ev["std"],
            "relative_std": ev["relative_std"],
            "correlation": ev["correlation"],
            "phases": [p.to_dict() for p in self.phases],
            "default": {**self.reference.to_dict(), "floor_used": self.reference.to_dict()["floor"]},
            "starts": list(self.starts),
            "chosen_start": self.candidates[self.chosen].start if self.candidates else None,
            "chosen_search": self.candidates[self.chosen].search if self.candidates else None,
            "elapsed_s": self.elapsed,
            "platform": self.trajectory.geometry.to_dict(),
            "warnings": list(self.warnings),
        }

    def to_yaml_dict(self) -> dict[str, Any]:
        """The trajectory file (YAML segments, docs/simulation.md) that ``simulate`` and ``feedforward`` read."""
        g = self.trajectory.geometry
        rot = [float(x) for x in nominal_steering(g, Mode.ROTATION)]
        st = self.settings
        align = {"pause": st.pause, "rate": st.align_rate, "acceleration": st.align_acceleration}
        ph = {p.name: p for p in self.phases}

        def series(p: PhaseDesign) -> dict[str, Any]:
            return {"base_frequency": p.series.base_frequency, "a": list(p.series.a), "b": list(p.series.b)}

        return {
            "plan": {"objective": self.objective, "cond": self.evaluation.cond,
                     "floor": {"length": self.floor.length, "width": self.floor.width},
                     "duration": self.evaluation.duration, "platform": g.to_dict()},
            "segments": [
                {"name": "align", "to": [0.0, 0.0], **align},
                {"name": "steer_left", "mode": "1", "fourier": {"alpha_l": series(ph["steer_left"])}},
                {"name": "align", "to": [0.0, 0.0], **align},
                {"name": "steer_right", "mode": "1", "fourier": {"alpha_r": series(ph["steer_right"])}},
                {"name": "align", "to": [0.0, 0.0], **align},
                {"name": "straight", "mode": "2s", "fourier": series(ph["straight"])},
                {"name": "align", "to": rot, **align},
                {"name": "rotation", "mode": "4", "fourier": series(ph["rotation"])},
                {"name": "align", "to": [0.0, 0.0], **align},
            ],
        }


def combine(plans: tuple[Plan, ...] | list[Plan], searches: tuple[str, ...] | list[str]) -> Plan:
    """One plan whose candidates are those of ``plans`` (the same vehicle, floor and duration, planned with
    the searches named ``searches``), in that order: the first plan's best start stays the plan and rank 0,
    the one a check on the simulator keeps unless another is measured better
    (:func:`agvdyn.plan_check.verify_plan`; ``agvdyn plan --search narrow,wide``). The predicted objectives
    of different searches are not compared."""
    if not plans or len(plans) != len(searches):
        raise ValueError(f"combine: expected one search name per plan, got {len(plans)} plans and {len(searches)} names")
    first = plans[0]
    for p in plans[1:]:
        if p.trajectory.geometry != first.trajectory.geometry or p.floor != first.floor or \
                abs(p.reference.duration - first.reference.duration) > 1e-9:
            raise ValueError("combine: the plans differ in vehicle, floor or duration")
    pool = [c for p in plans for c in p.candidates]
    names = [name for p, name in zip(plans, searches) for _ in p.candidates]
    pool = [replace(c, rank=i, search=name) for i, (c, name) in enumerate(zip(pool, names))]
    if not pool:
        raise ValueError("combine: the plans keep no candidates (PlanSettings.candidates >= 1)")
    starts = tuple({**st, "search": name} for p, name in zip(plans, searches) for st in p.starts)
    return replace(first, starts=starts, elapsed=sum(p.elapsed for p in plans), candidates=tuple(pool),
                   chosen=0).choose(0)
