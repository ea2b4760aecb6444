"""Figures in the manner of the paper: Fig. 5 (identification), Fig. 6 (validation), Table 2.

Every function takes a result object and returns a :class:`matplotlib.figure.Figure` built
without pyplot (no global state, works headless with the Agg canvas).
"""
from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from agvdyn.platform import PAPER_PARAMETERS, PAPER_STD, PARAMETER_NAMES

__all__ = ["identification_figure", "validation_figure", "parameter_figure"]

#: Most points drawn per line (longer signals are decimated for drawing only).
MAX_POINTS = 4000

_UNITS = {"alpha_l": "N m", "alpha_r": "N m", "alpha_v": "N m", "gamma_ch": "N m", "x_ch": "N", "y_ch": "N"}
_SYMBOLS = {"alpha_l": r"$\alpha_l$", "alpha_r": r"$\alpha_r$", "alpha_v": r"$\alpha_v$",
            "gamma_ch": r"$\gamma_{ch}$", "x_ch": r"$x_{ch}$", "y_ch": r"$y_{ch}$"}


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _panels(blocks, p, *, kept_only: bool, offsets=None):
    """(title, t, measured, model, kept) per segment and coordinate, runs of one segment joined."""
    panels: dict[str, list] = {}
    for b in blocks:
        model = b.model_torque(p, offsets)
        for j, coord in enumerate(b.coordinates):
            if kept_only and not b.keep[:, j].any():
                continue  # e.g. the resting side while the other side steers
            key = f"{b.segment}: {coord}"
            entry = panels.setdefault(key, [coord, [], [], [], []])
            entry[1].append(b.t)
            entry[2].append(b.torque[:, j])
            entry[3].append(model[:, j])
            entry[4].append(b.keep[:, j])
    return [(k, v[0], *(np.concatenate(x) for x in v[1:])) for k, v in panels.items()]


def _draw(ax, t, measured, model, kept, *, mask_stiction: bool) -> None:
    step = max(1, t.size // MAX_POINTS)
    sl = slice(None, None, step)
    meas = np.where(kept, measured, np.nan) if mask_stiction else measured
    mod = np.where(kept, model, np.nan) if mask_stiction else model
    ax.plot(t[sl], meas[sl], color="0.55", lw=1.2, label="measured  $H_k^T B u$")
    ax.plot(t[sl], mod[sl], color="C3", lw=0.9, ls="--", label=r"model  $H_k^T \Theta\, p$")
    if mask_stiction:
        dropped = ~kept[sl]
        if dropped.any():
            ax.plot(t[sl][dropped], measured[sl][dropped], ".", color="0.8", ms=1.5, label="stiction rows (dropped)")
    ax.grid(True, lw=0.3)


def _torque_figure(blocks, p, title: str, *, mask_stiction: bool, scores: dict[str, str] | None = None,
                   offsets=None) -> Figure:
    panels = _panels(blocks, p, kept_only=mask_stiction, offsets=offsets)
    n = max(1, len(panels))
    cols = 1 if n == 1 else 2
    rows = int(np.ceil(n / cols))
    fig = _new_figure(6.0 * cols, 2.4 * rows + 0.6)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, (key, coord, t, measured, model, kept) in zip(axes, panels):
        _draw(ax, t, measured, model, kept, mask_stiction=mask_stiction)
        label = key.split(":")[0] + ": " + _SYMBOLS.get(coord, coord)
        if scores and key.replace(": ", ":") in scores:
            label += f"   ({scores[key.replace(': ', ':')]})"
        ax.set_title(label, fontsize=9)
        ax.set_ylabel(f"generalized torque [{_UNITS.get(coord, '')}]", fontsize=8)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    if panels:
        axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=10)
    return fig


def identification_figure(identification) -> Figure:
    """Fig. 5: measured vs model generalized torques of each identification segment (kept rows);
    the model includes the estimated motor-torque offsets when there are any."""
    scores = {k: f"residual RMS {v:.3g}" for k, v in identification.residual_rms.items()}
    return _torque_figure(identification.blocks, identification.parameters.to_vector(),
                          "Identification experiment: generalized torques (cf. Fig. 5)",
                          mask_stiction=True, scores=scores, offsets=identification.offset_vector)


def validation_figure(validation) -> Figure:
    """Fig. 6: measured vs predicted generalized torques of the validation log (stiction rows kept)."""
    scores = {k: f"NRMSE {v:.3f}, without stiction {validation.nrmse_moving[k]:.3f}"
              for k, v in validation.nrmse.items()}
    return _torque_figure(validation.blocks, validation.parameters.to_vector(),
                          "Validation experiment: generalized torques (cf. Fig. 6)",
                          mask_stiction=False, scores=scores)


def parameter_figure(identification, reference=PAPER_PARAMETERS, reference_std=PAPER_STD) -> Figure:
    """Relative deviation of each estimated parameter from the reference, with +-3 std bars."""
    names = [n for n in PARAMETER_NAMES if n not in identification.fixed]
    ref = np.array([getattr(reference, n) for n in names])
    est = np.array([getattr(identification.parameters, n) for n in names])
    std = np.array([identification.std.get(n, np.nan) for n in names])
    ref_std = np.array([reference_std.get(n, np.nan) for n in names])
    fig = _new_figure(7.0, 3.2)
    ax = fig.subplots()
    x = np.arange(len(names))
    ax.axhspan(-5, 5, color="C2", alpha=0.12, label="within 5 %")
    ax.errorbar(x - 0.12, 100 * (est / ref - 1), yerr=300 * std / np.abs(ref), fmt="o", color="C0", ms=4,
                capsize=3, label="estimate, +-3 std")
    ax.errorbar(x + 0.12, np.zeros_like(ref), yerr=300 * ref_std / np.abs(ref), fmt="none", ecolor="0.6",
                capsize=3, label="Table 2, +-3 std")
    ax.axhline(0, color="0.3", lw=0.6)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("deviation from reference [%]", fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", lw=0.3)
    ax.set_title("Identified parameters relative to the reference (Table 2)", fontsize=10)
    return fig
