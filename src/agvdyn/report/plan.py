"""The excitation plan behind the identification logs (issue 11): the plan file ``agvdyn plan``
wrote, its floor rectangle and planned path, the path the vehicle actually drove (odometry,
eq. 3), the floor used against the floor available, and the predicted std next to the
identified ones.

A plan is found two ways: given (``agvdyn report --plan FILE``), or from a simulated log's
sidecar, whose ``experiment`` is the stem of the trajectory file it was simulated from; the
file ``<stem>.yaml`` (or ``.yml``) is looked for next to the log, then in the working directory,
and used only when it is a plan file (a ``plan:`` header) of the same platform that occupies
the floor the sidecar records.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from agvdyn.platform import PAPER_PARAMETERS, Geometry, Parameters
from agvdyn.trajectories import EXPERIMENTS, FloorSpace, Trajectory, TrajectoryError, read_trajectory

__all__ = ["PlanFile", "DrivenPath", "ExcitationPlan", "read_plan", "plan_of_logs", "driven_path",
           "excitation_plan", "MAX_DRIVEN"]
# The section of the report (its numbers, figure and HTML) is in agvdyn.report.plan_section.

#: At most this many driven paths are drawn (one per identification log).
MAX_DRIVEN = 4
#: The floor a sidecar records and the one the plan file occupies agree within this (m).
FLOOR_TOLERANCE = 1e-3


@dataclass(frozen=True, eq=False)
class PlanFile:
    """A trajectory file read for the report: its ``trajectory`` and, from its ``plan:`` header
    (None without one), the floor available, the objective and the predicted cond."""

    path: Path
    trajectory: Trajectory
    floor: FloorSpace | None = None
    objective: str | None = None
    cond: float | None = None


@dataclass(frozen=True, eq=False)
class DrivenPath:
    """The chassis pose ``(N, 3)`` = (X, Y, gamma) of one log by odometry (eq. 3), from its first
    sample, and the floor it occupies (sec. 6.2, as for a planned path)."""

    source: str
    t: np.ndarray
    pose: np.ndarray
    floor: FloorSpace


@dataclass(frozen=True, eq=False)
class ExcitationPlan:
    """What the report's "Excitation plan" section shows. ``found``: ``given`` (``--plan``) or
    ``sidecar``; ``predicted_std``: the planner's prediction for the plan's motion (absolute,
    B_w known), ``parameters``: the values the relative std refer to and ``parameters_label``
    which they are."""

    file: PlanFile
    found: Literal["given", "sidecar"]
    used: FloorSpace
    driven: tuple[DrivenPath, ...]
    predicted_cond: float
    predicted_std: Mapping[str, float]
    parameters: Parameters
    parameters_label: str

    def to_dict(self) -> dict[str, Any]:
        """The ``plan`` entry of ``agvdyn report --json``."""
        def rect(f: FloorSpace | None) -> dict[str, float] | None:
            return None if f is None else {"length": f.length, "width": f.width}

        return {"path": str(self.file.path), "found": self.found, "objective": self.file.objective,
                "cond": self.file.cond if self.file.cond is not None else self.predicted_cond,
                "floor": rect(self.file.floor), "floor_used": rect(self.used),
                "duration": self.file.trajectory.duration,
                "predicted_std": {k: _json_float(v) for k, v in self.predicted_std.items()},
                "driven": [{"log": d.source, "floor_used": rect(d.floor)} for d in self.driven]}


def _json_float(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _number(block: Mapping[str, Any], key: str) -> float | None:
    value = block.get(key)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def read_plan(path: str | os.PathLike, geometry: Geometry) -> PlanFile:
    """The trajectory file at ``path`` (a plan file of ``agvdyn plan`` or any YAML/CSV trajectory)
    on ``geometry``. Raises ValueError naming the file: missing, unreadable, not a trajectory, or
    planned for another platform."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"plan file {path}: no such file")
    block: Mapping[str, Any] = {}
    if path.suffix.lower() in (".yaml", ".yml"):
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise ValueError(f"plan file {path}: cannot be read as YAML: {exc}") from exc
        if not isinstance(data, dict) or "segments" not in data:
            raise ValueError(f"plan file {path}: expected a trajectory file with 'segments' (as agvdyn plan "
                             "writes)")
        block = data.get("plan") if isinstance(data.get("plan"), dict) else {}
    planned = block.get("platform")
    if isinstance(planned, dict):
        try:
            other = Geometry(**{k: planned[k] for k in ("l", "b", "a", "r", "i_G")}, name=str(planned.get("name")))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"plan file {path}: plan.platform: {exc}") from exc
        if not other.same_shape(geometry):
            raise ValueError(f"plan file {path}: planned for the platform {other.describe()}, but the logs are of "
                             f"{geometry.describe()}")
    try:
        traj = read_trajectory(path, geometry)
    except TrajectoryError as exc:
        text = str(exc)
        raise ValueError(text if text.startswith(str(path)) else f"plan file {path}: {text}") from exc
    floor = block.get("floor")
    rect = None
    if isinstance(floor, dict) and _number(floor, "length") and _number(floor, "width"):
        rect = FloorSpace(_number(floor, "length"), _number(floor, "width"))
    objective = block.get("objective")
    return PlanFile(path, traj, rect, None if objective is None else str(objective), _number(block, "cond"))


def _experiment(log: Any) -> str | None:
    side = getattr(log, "sidecar", None) or {}
    name = side.get("experiment") if isinstance(side, dict) else None
    return str(name) if isinstance(name, str) and name.strip() else None


def _candidates(log: Any, name: str) -> list[Path]:
    """Where the trajectory file ``name`` of a sidecar may be: next to the log, then the working directory."""
    given = Path(name)
    names = [given] if given.suffix.lower() in (".yaml", ".yml") else [Path(name + ".yaml"), Path(name + ".yml")]
    roots = [Path(log.path).parent] if getattr(log, "path", None) else []
    roots.append(Path.cwd())
    out: list[Path] = []
    for root in roots:
        for n in names:
            p = n if n.is_absolute() else root / n
            if p not in out:
                out.append(p)
    return out


def plan_of_logs(logs: Sequence[Any], geometry: Geometry) -> tuple[PlanFile | None, tuple[str, ...]]:
    """The plan file the first simulated log was driven from, found by its sidecar (module
    docstring), and notes on files looked for but not used; (None, notes) without one."""
    notes: list[str] = []
    for log in logs:
        name = _experiment(log)
        if name is None or name.strip().lower().replace("_", "-") in EXPERIMENTS:
            continue
        where = getattr(log, "path", None) or "<log>"
        looked = _candidates(log, name)
        found = [p for p in looked if p.is_file()]
        if not found:
            notes.append(f"{where} was simulated from the trajectory '{name}', but no plan file was found (looked "
                         f"for {', '.join(str(p) for p in looked)}): pass --plan FILE to show it.")
            continue
        for path in found:
            try:
                plan_file = read_plan(path, geometry)
            except ValueError as exc:
                notes.append(f"{path} not shown: {exc}")
                continue
            if plan_file.floor is None:
                notes.append(f"{path} not shown: a trajectory file without a plan: header (not written by agvdyn plan)")
                continue
            side = log.sidecar.get("floor_space")
            used = plan_file.trajectory.floor_space()
            if isinstance(side, dict) and not _same_floor(side, used):
                notes.append(f"{path} not shown: it occupies {used.length:.3f} m x {used.width:.3f} m but the sidecar "
                             f"of {where} records {side.get('length')} m x {side.get('width')} m (another plan)")
                continue
            return plan_file, tuple(notes)
    return None, tuple(notes)


def _same_floor(recorded: Mapping[str, Any], used: FloorSpace) -> bool:
    """True when a sidecar's ``floor_space`` is ``used`` within :data:`FLOOR_TOLERANCE`."""
    return all(isinstance(recorded.get(k), (int, float))
               and abs(float(recorded[k]) - getattr(used, k)) <= FLOOR_TOLERANCE for k in ("length", "width"))


def driven_path(log: Any, geometry: Geometry) -> DrivenPath:
    """The path a log drove, by odometry (eq. 3) from the measured steering and wheel angles
    (rates by central differences in time), integrated by the trapezoidal rule with the log's
    own time steps (dropouts included)."""
    from agvdyn.odometry import odometry

    t = np.asarray(log.t, dtype=float)
    alpha, beta = np.asarray(log.alpha, dtype=float), np.asarray(log.beta, dtype=float)
    twist = odometry(geometry, alpha, np.gradient(alpha, t, axis=0), np.gradient(beta, t, axis=0))
    dt = np.diff(t)
    gamma = np.concatenate([[0.0], np.cumsum(0.5 * dt * (twist[1:, 2] + twist[:-1, 2]))])
    c, s = np.cos(gamma), np.sin(gamma)
    world = np.stack([c * twist[:, 0] - s * twist[:, 1], s * twist[:, 0] + c * twist[:, 1]], axis=1)
    xy = np.concatenate([np.zeros((1, 2)), np.cumsum(0.5 * dt[:, None] * (world[1:] + world[:-1]), axis=0)])
    pose = np.column_stack([xy, gamma])
    g = geometry
    floor = FloorSpace(g.l + 2 * float(np.max(np.abs(xy[:, 0]))),
                       math.hypot(g.l, g.b) + 2 * abs(g.a) + 2 * float(np.max(np.abs(xy[:, 1]))))
    return DrivenPath(str(getattr(log, "path", None) or "<log>"), t - t[0], pose, floor)


def _driven_logs(logs: Sequence[Any], plan_file: PlanFile) -> list[Any]:
    """The logs driven from the plan: those whose sidecar names it, or names no trajectory at all
    (recorded on the vehicle); not those simulated from another experiment."""
    stem = plan_file.path.stem
    return [log for log in logs if _experiment(log) in (None, stem, str(plan_file.path))]


def excitation_plan(logs: Sequence[Any], geometry: Geometry, plan: PlanFile | str | os.PathLike | None = None, *,
                    parameters: Parameters | None = None, parameters_label: str | None = None
                    ) -> tuple[ExcitationPlan | None, tuple[str, ...]]:
    """The report's excitation plan: ``plan`` given (a path or a read :class:`PlanFile`), else the
    one the logs' sidecars lead to (:func:`plan_of_logs`); (None, notes) without one.

    ``parameters``: the values the predicted relative std refer to (the identified ones); default:
    Table 2 with B_w = 0.121, the planner's nominal values.
    """
    from agvdyn.trajectories.planner import evaluate_sequence

    if plan is None:
        plan_file, notes = plan_of_logs(logs, geometry)
        found: Literal["given", "sidecar"] = "sidecar"
        if plan_file is None:
            return None, notes
    else:
        plan_file = plan if isinstance(plan, PlanFile) else read_plan(plan, geometry)
        found, notes = "given", ()
    driven = tuple(driven_path(log, geometry) for log in _driven_logs(logs, plan_file)[:MAX_DRIVEN])
    if parameters is None:
        parameters, parameters_label = PAPER_PARAMETERS, "Table 2 with B_w = 0.121 (the planner's nominal values)"
    notes = list(notes)
    try:
        ev = evaluate_sequence(plan_file.trajectory, parameters)
        cond, std = ev.cond, dict(ev.std)
    except (TrajectoryError, ValueError, np.linalg.LinAlgError) as exc:
        cond, std = math.nan, {}
        notes.append(f"no prediction for {plan_file.path}: {exc}")
    return ExcitationPlan(plan_file, found, plan_file.trajectory.floor_space(), driven, cond, std, parameters,
                          parameters_label or "the identified values"), tuple(notes)
