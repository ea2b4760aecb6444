"""plan_figure(): floor, path and predicted stds of a plan; draw_floor(): the floor panel alone (also the report's)."""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from agvdyn.trajectories.limits import FloorSpace
from agvdyn.trajectories.planner.result import Plan
from agvdyn.trajectories.planner.settings import FREE
from agvdyn.trajectories.segments import Trajectory

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


def plan_figure(plan_: Plan) -> "Figure":
    """The plan's floor rectangle with the path and footprint of the vehicle, and its phases over time
    (steering angles, chassis travel and heading) next to the default sequence's floor."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    traj = plan_.trajectory
    fig = Figure(figsize=(11, 6.5), layout="constrained")
    gs = fig.add_gridspec(2, 2, width_ratios=(1.1, 1))
    ax = fig.add_subplot(gs[:, 0])
    draw_floor(ax, traj, plan_.floor, used=plan_.evaluation.floor, default=plan_.reference.floor)
    ax.set_title(f"Floor: cond {plan_.evaluation.cond:.2f} (default {plan_.reference.cond:.2f})")
    pose = traj.pose()
    ax2 = fig.add_subplot(gs[0, 1])
    t = traj.t
    ax2.plot(t, traj.alpha[:, 0], label="alpha_l (rad)")
    ax2.plot(t, traj.alpha[:, 1], label="alpha_r (rad)")
    ax2.plot(t, pose[:, 0], label="x_ch (m)")
    ax2.plot(t, pose[:, 2], label="gamma_ch (rad)")
    for name, sl in traj.segment_slices():
        if name != "align":
            ax2.axvspan(t[sl.start], t[sl.stop - 1], alpha=0.07, color="black")
            ax2.text(t[sl.start], 1.01, name, fontsize=7, va="bottom", transform=ax2.get_xaxis_transform())
    ax2.set_xlabel("t (s)")
    ax2.legend(fontsize=7, ncol=2)
    ax2.set_title("Planned phases")
    ax3 = fig.add_subplot(gs[1, 1])
    names = list(FREE)
    x = np.arange(len(names))
    ax3.bar(x - 0.2, [100 * plan_.reference.relative_std[n] for n in names], 0.4, label="default", color="tab:gray")
    ax3.bar(x + 0.2, [100 * plan_.evaluation.relative_std[n] for n in names], 0.4, label="plan", color="tab:blue")
    ax3.set_xticks(x, names, rotation=45, fontsize=8)
    ax3.set_ylabel("predicted std (% of value)")
    ax3.set_yscale("log")
    ax3.legend(fontsize=8)
    return fig


def draw_floor(ax: "Axes", trajectory: Trajectory, floor: FloorSpace | None, *, used: FloorSpace | None = None,
               default: FloorSpace | None = None, driven: Sequence[tuple[str, np.ndarray]] = ()) -> "Axes":
    """``ax`` with the floor rectangle (centred on the start, as the plan is), the rectangles the plan
    (``used``) and the default sequence use, the rotation circle, the footprints at the ends of the
    travel, the planned chassis path and the ``driven`` paths ``(label, pose (N, 3))``."""
    from matplotlib.patches import Circle, Rectangle

    g = trajectory.geometry
    pose = trajectory.pose()
    radius = math.hypot(g.l, g.b) / 2 + abs(g.a)
    shown = [FloorSpace(2 * float(np.max(np.abs(pose[:, 0]))) + g.l, 2 * radius)]
    if floor is not None:
        ax.add_patch(Rectangle((-floor.length / 2, -floor.width / 2), floor.length, floor.width, fill=False, lw=2,
                               ec="black", label=f"floor {floor.length:g} m x {floor.width:g} m"))
        shown.append(floor)
    for rect, style, color, text in ((used, "--", "tab:blue", "plan uses"), (default, ":", "tab:gray", "default uses")):
        if rect is not None:
            ax.add_patch(Rectangle((-rect.length / 2, -rect.width / 2), rect.length, rect.width, fill=False, ls=style,
                                   ec=color, label=f"{text} {rect.length:.2f} m x {rect.width:.2f} m"))
            shown.append(rect)
    ax.add_patch(Circle((0, 0), radius, fill=False, ec="tab:orange", ls="-.", label="rotation"))
    xs = pose[:, 0]
    for x_end in (xs.min(), xs.max()):
        ax.add_patch(Rectangle((x_end - g.l / 2, -g.b / 2), g.l, g.b, alpha=0.15, color="tab:blue"))
    ax.plot(pose[:, 0], pose[:, 1], color="tab:blue", lw=1.5, label="chassis centre")
    for (label, path), color in zip(driven, ("tab:red", "tab:green", "tab:purple", "tab:brown")):
        ax.plot(path[:, 0], path[:, 1], color=color, lw=1, ls="--", label=label)
        shown.append(FloorSpace(2 * float(np.max(np.abs(path[:, 0]))) + g.l, 2 * float(np.max(np.abs(path[:, 1])))))
    ax.set_aspect("equal")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.legend(loc="upper left", fontsize=8)
    margin = 0.2
    half_length = max(f.length for f in shown) / 2 + margin
    half_width = max(f.width for f in shown) / 2 + margin
    ax.set_xlim(-half_length, half_length)
    ax.set_ylim(-half_width, half_width)
    return ax
