"""plan_figure(): floor, path and predicted stds of a plan."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from agvdyn.trajectories.planner.optimize import Plan
from agvdyn.trajectories.planner.settings import FREE

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def plan_figure(plan_: Plan) -> "Figure":
    """The plan's floor rectangle with the path and footprint of the vehicle, and its phases over time
    (steering angles, chassis travel and heading) next to the default sequence's floor."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    traj = plan_.trajectory
    g = traj.geometry
    fig = Figure(figsize=(11, 6.5), layout="constrained")
    gs = fig.add_gridspec(2, 2, width_ratios=(1.1, 1))
    ax = fig.add_subplot(gs[:, 0])
    pose = traj.pose()
    fl = plan_.floor
    ax.add_patch(Rectangle((-fl.length / 2, -fl.width / 2), fl.length, fl.width, fill=False, lw=2,
                           ec="black", label=f"floor {fl.length:g} m x {fl.width:g} m"))
    used = plan_.evaluation.floor
    ax.add_patch(Rectangle((-used.length / 2, -used.width / 2), used.length, used.width, fill=False, ls="--",
                           ec="tab:blue", label=f"plan uses {used.length:.2f} m x {used.width:.2f} m"))
    ref = plan_.reference.floor
    ax.add_patch(Rectangle((-ref.length / 2, -ref.width / 2), ref.length, ref.width, fill=False, ls=":",
                           ec="tab:gray", label=f"default uses {ref.length:.2f} m x {ref.width:.2f} m"))
    radius = math.hypot(g.l, g.b) / 2 + abs(g.a)
    ax.add_patch(Circle((0, 0), radius, fill=False, ec="tab:orange", ls="-.", label="rotation"))
    xs = pose[:, 0]
    for x_end in (xs.min(), xs.max()):
        ax.add_patch(Rectangle((x_end - g.l / 2, -g.b / 2), g.l, g.b, alpha=0.15, color="tab:blue"))
    ax.plot(pose[:, 0], pose[:, 1], color="tab:blue", lw=1.5, label="chassis centre")
    ax.set_aspect("equal")
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.set_title(f"Floor: cond {plan_.evaluation.cond:.2f} (default {plan_.reference.cond:.2f})")
    ax.legend(loc="upper left", fontsize=8)
    margin = 0.2
    ax.set_xlim(-fl.length / 2 - margin, fl.length / 2 + margin)
    ax.set_ylim(-max(fl.width, 2 * radius) / 2 - margin, max(fl.width, 2 * radius) / 2 + margin)
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
