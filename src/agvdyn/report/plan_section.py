"""The report's "Excitation plan" section: :func:`plan_section` computes its numbers and figure
input from an :class:`~agvdyn.report.plan.ExcitationPlan` (assembly), :func:`plan_report_figure`
draws, :func:`plan_html` formats."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from agvdyn.platform import PARAMETER_UNITS
from agvdyn.report._format import esc, img, num, percent, table, unit
from agvdyn.report.plan import ExcitationPlan
from agvdyn.trajectories import FloorSpace, Trajectory

__all__ = ["PlanFigure", "PlanSection", "plan_section", "plan_report_figure", "plan_html"]


def _thin(a: np.ndarray, points: int = 4000) -> np.ndarray:
    """Every k-th row of ``a``, at most about ``points`` rows (enough for a line at 1,200 px)."""
    return a[::max(1, len(a) // points)]


@dataclass(frozen=True, eq=False)
class PlanFigure:
    """What the plan's figure draws: the planned trajectory on its floor (``floor``, ``used``), the
    driven paths ``(label, pose)``, the planned pose over time ``t``, ``pose``, the first driven
    pose over its time (None: nothing driven) and the spans of the experiments (not ``align``)."""

    name: str
    trajectory: Trajectory
    floor: FloorSpace | None
    used: FloorSpace
    driven: tuple[tuple[str, np.ndarray], ...]
    t: np.ndarray
    pose: np.ndarray
    first_driven: tuple[np.ndarray, np.ndarray] | None
    spans: tuple[tuple[float, float], ...]


@dataclass(frozen=True, eq=False)
class PlanSection:
    """The section's numbers: the file and how it was found, the floor available, used by the plan
    (and its share of the floor) and driven, cond predicted and identified, durations, predicted
    against identified std ``(name, predicted, % of value, identified, % of value, unit)``,
    warnings and notes; ``figure`` None: no plan (only the notes are shown)."""

    notes: tuple[str, ...]
    path: str = ""
    found: Literal["given", "sidecar"] = "given"
    objective: str | None = None
    floor: FloorSpace | None = None
    used: FloorSpace | None = None
    used_share_pct: tuple[float, float] | None = None
    driven: tuple[tuple[str, FloorSpace], ...] = ()
    cond_predicted: float = float("nan")
    cond_identified: float | None = None
    planned_duration: float = float("nan")
    driven_durations: tuple[float, ...] = ()
    std_rows: tuple[tuple[str, float, float | None, float | None, float | None, str], ...] = ()
    parameters_label: str = ""
    warnings: tuple[str, ...] = ()
    figure: PlanFigure | None = None


def _figure(plan: ExcitationPlan) -> PlanFigure:
    traj = plan.file.trajectory
    driven = tuple((f"driven, {Path(d.source).name}", _thin(d.pose)) for d in plan.driven)
    first = (_thin(plan.driven[0].t), _thin(plan.driven[0].pose)) if plan.driven else None
    spans = tuple((float(traj.t[sl.start]), float(traj.t[sl.stop - 1])) for name, sl in traj.segment_slices()
                  if name != "align")
    return PlanFigure(plan.file.path.name, traj, plan.file.floor, plan.used, driven, _thin(traj.t),
                      _thin(traj.pose()), first, spans)


def plan_section(plan: ExcitationPlan | None, notes: Sequence[str] = (), identification: Any = None
                 ) -> PlanSection | None:
    """The section of ``plan`` (None: the notes alone, or nothing without notes)."""
    if plan is None:
        return PlanSection(tuple(notes)) if notes else None
    f = plan.file
    warnings = list(notes)
    share = None
    if f.floor is not None:
        share = (100 * plan.used.length / f.floor.length, 100 * plan.used.width / f.floor.width)
    for d in plan.driven:
        if f.floor is not None and (d.floor.length > f.floor.length + 0.05 or d.floor.width > f.floor.width + 0.05):
            warnings.append(f"{d.source}: the path driven (odometry) needs {d.floor.length:.2f} m x "
                            f"{d.floor.width:.2f} m, more than the floor available.")
    rows = []
    ident_std = identification.std if identification is not None else {}
    for name, std in plan.predicted_std.items():
        value = getattr(plan.parameters, name)
        got = ident_std.get(name)
        rows.append((name, std, 100 * std / abs(value) if value else None, got,
                     100 * got / abs(value) if got is not None and value else None, PARAMETER_UNITS[name]))
    return PlanSection(
        (), str(f.path), plan.found, f.objective, f.floor, plan.used, share,
        tuple((Path(d.source).name, d.floor) for d in plan.driven),
        f.cond if f.cond is not None else plan.predicted_cond,
        None if identification is None else identification.condition_number, f.trajectory.duration,
        tuple(float(d.t[-1]) for d in plan.driven), tuple(rows), plan.parameters_label, tuple(warnings),
        _figure(plan))


def plan_report_figure(figure: PlanFigure):
    """The floor (available, used, rotation circle) with the planned and driven paths, and the
    chassis pose over time, planned against driven."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    from agvdyn.trajectories.planner.figure import draw_floor

    fig = Figure(figsize=(12, 5.6), layout="constrained")
    gs = fig.add_gridspec(3, 2, width_ratios=(1.15, 1), height_ratios=(1, 1, 0.22))
    ax = fig.add_subplot(gs[:2, 0])
    draw_floor(ax, figure.trajectory, figure.floor, used=figure.used, driven=list(figure.driven))
    ax.get_legend().remove()  # below the floor instead, which stays visible
    legend_ax = fig.add_subplot(gs[2, 0])
    legend_ax.axis("off")
    legend_ax.legend(*ax.get_legend_handles_labels(), loc="center", ncol=3, fontsize=8)
    ax.set_title(f"Floor and chassis path ({figure.name})")
    panels = ((fig.add_subplot(gs[0, 1]), ((0, "X (m)"), (1, "Y (m)"))),
              (fig.add_subplot(gs[1:, 1]), ((2, "gamma (rad)"),)))
    for axis, columns in panels:
        for col, label in columns:
            line, = axis.plot(figure.t, figure.pose[:, col], lw=1.2, label=f"{label} planned")
            if figure.first_driven is not None:
                t, pose = figure.first_driven
                axis.plot(t, pose[:, col], ls="--", lw=1, color=line.get_color(), label=f"{label} driven")
        for start, end in figure.spans:
            axis.axvspan(start, end, alpha=0.07, color="black")
        axis.legend(fontsize=7, ncol=2, loc="upper left")
    panels[0][0].set_title("Chassis pose: planned, and driven by odometry" if figure.driven
                           else "Planned chassis pose")
    panels[1][0].set_xlabel("t (s)")
    return fig


def _rect(f: FloorSpace) -> str:
    return f"{num(f.length, 3)}&nbsp;m &times; {num(f.width, 3)}&nbsp;m"


def plan_html(section: PlanSection | None) -> str:
    """The "Excitation plan" section: facts, figure and predicted against identified std; a
    one-line note when a plan was looked for and not shown; nothing without either."""
    if section is None:
        return ""
    if section.figure is None:
        return ('<section id="plan"><h2>Excitation plan</h2>'
                + "".join(f'<p class="note">{esc(n)}</p>' for n in section.notes) + "</section>")
    s = section
    how = "given with <code>--plan</code>" if s.found == "given" else "found from the log's sidecar"
    facts = [["plan file", f"<code>{esc(s.path)}</code> ({how})"]]
    if s.objective:
        facts.append(["objective", esc(s.objective)])
    if s.floor is not None:
        facts.append(["floor available", _rect(s.floor)])
    used = _rect(s.used)
    if s.used_share_pct is not None:
        used += (f" ({percent(s.used_share_pct[0], 3)} of the length, "
                 f"{percent(s.used_share_pct[1], 3)} of the width)")
    facts.append(["floor the plan uses", used])
    for name, floor in s.driven:
        facts.append([f"floor driven, by odometry: <code>{esc(name)}</code>", _rect(floor)])
    cond = f"{num(s.cond_predicted, 4)} predicted"
    if s.cond_identified is not None:
        cond += f"; {num(s.cond_identified, 4)} identified"
    facts.append(["cond(&Theta;<sub>1,w</sub><sup>T</sup>&Theta;<sub>1,w</sub>)", cond])
    durations = "; ".join(f"{num(d, 4)}&nbsp;s driven" for d in s.driven_durations)
    planned = f"{num(s.planned_duration, 4)}&nbsp;s planned"
    facts.append(["duration", f"{planned}; {durations}" if durations else planned])
    parts = ['<section id="plan"><h2>Excitation plan</h2>',
             '<div class="scroll">' + table(None, facts, align="ll") + "</div>",
             img(plan_report_figure(s.figure), "Floor rectangle available (black), the rectangle the plan uses "
                 "(dashed), the planned chassis path" + (" and the path driven by odometry" if s.driven else "")
                 + "; right: the chassis pose over time.")]
    if s.std_rows:
        rows = [[esc(name), num(std, 2), percent(pct, 2) if pct is not None else "&ndash;", num(got, 2),
                 percent(got_pct, 2) if got_pct is not None else "&ndash;", unit(u)]
                for name, std, pct, got, got_pct, u in s.std_rows]
        parts.append("<h3>Predicted and identified std</h3>")
        parts.append(table(["parameter", "predicted std", "% of value", "identified std", "% of value", "unit"], rows,
                           align="lrrrrl"))
        parts.append(f'<p class="note">Predicted by the planner (agvdyn.trajectories.planner.evaluate_sequence) from '
                     f"the planned motion with its noise levels and the identification's stiction mask, B_w known; "
                     f"percentages of {esc(s.parameters_label)}.</p>")
    if s.warnings:
        parts.append("<ul>" + "".join(f"<li>{esc(w)}</li>" for w in s.warnings) + "</ul>")
    parts.append("</section>")
    return "".join(parts)
