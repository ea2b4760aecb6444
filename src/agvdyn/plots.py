"""Figures of the report: Fig. 5 (identification fit), Fig. 6 (validation), parameters against a
reference, parameter correlation, residuals with their autocorrelation, and the data-quality
timeline of each log.

Every function draws precomputed data (:mod:`agvdyn.figure_data`; given a result object instead,
it computes that data first) and returns a :class:`matplotlib.figure.Figure` built without pyplot
(no global state, works headless with the Agg canvas).

Model torques are drawn only on the rows the fit keeps (``EquationBlock.keep``: stiction rows,
slip, filter edges and their guards left out), in Fig. 5 and Fig. 6 alike: at standstill the
tanh Coulomb term of the model switches with the sign of a velocity that is only noise, and
drawing it there shows chatter the fit never used.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from agvdyn import figure_data as data
from agvdyn.platform import PAPER_PARAMETERS, PAPER_STD

__all__ = ["identification_figure", "validation_figure", "parameter_figure", "correlation_figure",
           "residual_figure", "quality_figure", "mode_name", "MODE_COLORS"]

#: Most points drawn per line (longer signals are decimated for drawing only).
MAX_POINTS = 4000
#: A time step longer than this many median steps breaks a drawn line (dropouts, other runs).
BREAK_STEPS = 3.0

_UNITS = {"alpha_l": "N m", "alpha_r": "N m", "alpha_v": "N m", "gamma_ch": "N m", "x_ch": "N", "y_ch": "N"}
_SYMBOLS = {"alpha_l": r"$\alpha_l$", "alpha_r": r"$\alpha_r$", "alpha_v": r"$\alpha_v$",
            "gamma_ch": r"$\gamma_{ch}$", "x_ch": r"$x_{ch}$", "y_ch": r"$y_{ch}$"}

#: One colour per motion mode label (and "none" for rows in no mode), shared by all figures.
MODE_COLORS = {"1": "#4c72b0", "2": "#dd8452", "2s": "#55a868", "3": "#8172b3", "4": "#c44e52", "none": "#b0b0b0"}
_MODE_NAMES = {"1": "1 wheel alignment", "2": "2 car-like", "2s": "2s straight", "3": "3 lateral",
               "4": "4 rotation", "none": "no mode"}


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _decimated(t: np.ndarray, *ys: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every k-th point (at most MAX_POINTS), with NaN inserted where the time jumps, so that a line
    is never drawn across a dropout or between two runs far apart."""
    step = max(1, t.size // MAX_POINTS)
    t = t[::step]
    ys = tuple(np.asarray(y, dtype=float)[::step] for y in ys)
    if t.size > 2:
        dt = np.diff(t)
        jumps = np.flatnonzero(dt > BREAK_STEPS * np.median(dt)) + 1
        if jumps.size:
            t = np.insert(t.astype(float), jumps, np.nan)
            ys = tuple(np.insert(y, jumps, np.nan) for y in ys)
    return (t, *ys)


def _draw(ax, t, measured, model, kept) -> None:
    """Measured torque on every row; model only on the kept rows; left-out rows shaded."""
    td, meas, mod, keep = _decimated(t, measured, np.where(kept, model, np.nan), kept.astype(float))
    dropped = keep < 0.5  # NaN (breaks) compare False: nothing shaded there
    if dropped.any():
        ax.fill_between(td, 0, 1, where=dropped, transform=ax.get_xaxis_transform(), color="0.93", lw=0,
                        label="rows left out (model not drawn)")
    ax.plot(td, meas, color="0.45", lw=1.0, label="measured  $H_k^T B u$")
    ax.plot(td, mod, color="C3", lw=1.0, ls="--", label=r"model  $H_k^T \Theta\, p$")
    ax.grid(True, lw=0.3)


def _torque_figure(figure: data.TorqueFigure) -> Figure:
    panels = figure.panels
    n = max(1, len(panels))
    cols = 1 if n == 1 else 2
    rows = int(np.ceil(n / cols))
    fig = _new_figure(6.0 * cols, 2.3 * rows + 0.7)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, panel in zip(axes, panels):
        _draw(ax, panel.t, panel.measured, panel.model, panel.kept)
        head, _, _ = panel.key.rpartition(":")
        label = f"{head}: {_SYMBOLS.get(panel.coordinate, panel.coordinate)}"
        if panel.score:
            label += f"   ({panel.score})"
        ax.set_title(label, fontsize=9)
        ax.set_ylabel(f"generalized torque [{_UNITS.get(panel.coordinate, '')}]", fontsize=8)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    if panels:
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    fig.suptitle(figure.title, fontsize=10)
    return fig


def identification_figure(torques) -> Figure:
    """Fig. 5: measured vs model generalized torques of each identification segment; the model
    (with the estimated motor-torque offsets, when any) on the kept rows only. ``torques``:
    :func:`agvdyn.figure_data.identification_torques`, or the identification itself."""
    return _torque_figure(torques if isinstance(torques, data.TorqueFigure) else data.identification_torques(torques))


def validation_figure(torques) -> Figure:
    """Fig. 6: measured vs predicted generalized torques of the validation log; the prediction is
    drawn on the rows the NRMSE without stiction rows uses (stiction and edge rows shaded).
    ``torques``: :func:`agvdyn.figure_data.validation_torques`, or the validation itself."""
    return _torque_figure(torques if isinstance(torques, data.TorqueFigure) else data.validation_torques(torques))


def parameter_figure(deviations, reference=PAPER_PARAMETERS, reference_std=PAPER_STD, *,
                     label: str = "Table 2") -> Figure:
    """Relative deviation of each estimated parameter from a reference, with +-3 std bars.
    ``deviations``: :func:`agvdyn.figure_data.parameter_deviations`, or an identification
    (compared with ``reference``)."""
    d = deviations if isinstance(deviations, data.ParameterDeviations) else \
        data.parameter_deviations(deviations, reference, reference_std, label=label)
    fig = _new_figure(7.0, 3.0)
    ax = fig.subplots()
    x = np.arange(len(d.names))
    ax.axhspan(-5, 5, color="C2", alpha=0.12, label="within 5 %")
    ax.errorbar(x - 0.12, d.deviation_pct, yerr=d.bar_pct, fmt="o", color="C0", ms=4,
                capsize=3, label="estimate, +-3 std")
    if np.isfinite(d.reference_bar_pct).any():
        ax.errorbar(x + 0.12, np.zeros(len(d.names)), yerr=d.reference_bar_pct, fmt="none", ecolor="0.6",
                    capsize=3, label=f"{d.label}, +-3 std")
    ax.axhline(0, color="0.3", lw=0.6)
    ax.set_xticks(x, list(d.names), fontsize=8)
    ax.set_ylabel("deviation from reference [%]", fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", lw=0.3)
    ax.set_title(f"Identified parameters relative to the reference ({d.label})", fontsize=10)
    return fig


def correlation_figure(correlation) -> Figure:
    """Correlation matrix of the estimated parameters as a heatmap (values written in the cells).
    ``correlation``: :func:`agvdyn.figure_data.correlation_matrix`, or an identification."""
    c = correlation if isinstance(correlation, data.CorrelationMatrix) else data.correlation_matrix(correlation)
    names, r = list(c.names), c.matrix
    size = 1.2 + 0.48 * max(len(names), 2)
    fig = _new_figure(size + 1.0, size)
    ax = fig.subplots()
    image = ax.imshow(r, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_xticks(np.arange(len(names)), names, fontsize=8, rotation=45, ha="right")
    ax.set_yticks(np.arange(len(names)), names, fontsize=8)
    for i in range(len(names)):
        for j in range(len(names)):
            ax.text(j, i, f"{r[i, j]:.2f}", ha="center", va="center", fontsize=6.5,
                    color="white" if abs(r[i, j]) > 0.6 else "0.15")
    fig.colorbar(image, ax=ax, shrink=0.8, label="correlation")
    ax.set_title(f"Correlation of the estimates ({c.method} covariance)", fontsize=10)
    return fig


def residual_figure(residuals, *, max_lag_s: float = 1.5) -> Figure:
    """Residuals of the fit over time (left) and their autocorrelation (right), one row per
    generalized coordinate; the HAC bandwidth of the uncertainty, when there is one, is marked.
    ``residuals``: :func:`agvdyn.figure_data.residuals`, or an identification."""
    res = residuals if isinstance(residuals, data.Residuals) else data.residuals(residuals, max_lag_s=max_lag_s)
    dt, bandwidth, sources = res.dt, res.bandwidth, res.sources
    fig = _new_figure(12.0, 1.9 * max(len(res.panels), 1) + 0.6)
    axes = fig.subplots(max(len(res.panels), 1), 2, squeeze=False, width_ratios=[2.2, 1])
    for row, panel in enumerate(res.panels):
        coord = panel.coordinate
        ax, ax_acf = axes[row]
        for source, t_block, residual in panel.traces:
            t, drawn = _decimated(t_block, residual)
            ax.plot(t, drawn, lw=0.6, color=f"C{source % 10}")
        ax.axhline(0, color="0.3", lw=0.5)
        ax.set_ylabel(f"{_SYMBOLS.get(coord, coord)} [{_UNITS.get(coord, '')}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3)
        lags = np.arange(panel.acf.size) * dt
        ax_acf.plot(lags, panel.acf, color="C0", lw=1.0)
        band = 1.96 / np.sqrt(max(panel.rows, 1))
        ax_acf.axhspan(-band, band, color="0.85", lw=0, label="95 % band of white noise")
        if bandwidth:
            ax_acf.axvline(bandwidth * dt, color="C3", ls=":", lw=1.0, label=f"HAC bandwidth {bandwidth * dt:.2g} s")
        ax_acf.axhline(0, color="0.3", lw=0.5)
        ax_acf.set_ylim(-0.5, 1.05)
        ax_acf.tick_params(labelsize=7)
        ax_acf.grid(True, lw=0.3)
        if row == 0:
            ax.set_title("residual = measured - model (kept rows)", fontsize=9)
            ax_acf.set_title("autocorrelation of the residual", fontsize=9)
            ax_acf.legend(fontsize=7, loc="upper right")
    if res.panels:
        axes[-1][0].set_xlabel("t [s]", fontsize=8)
        axes[-1][1].set_xlabel("lag [s]", fontsize=8)
        if len(sources) > 1:
            fig.legend([Patch(color=f"C{i % 10}") for i in range(len(sources))], list(sources),
                       loc="outside lower center", ncols=min(len(sources), 3), fontsize=7, frameon=False)
    else:
        axes[0][0].set_visible(False)
        axes[0][1].set_visible(False)
    fig.suptitle("Residuals of the identification per generalized coordinate", fontsize=10)
    return fig


def _bars(ax, y: float, spans: Sequence[tuple[float, float]], color, height: float = 0.7, **kw) -> None:
    spans = [(a, max(b - a, 1e-9)) for a, b in spans]
    if spans:
        ax.broken_barh(spans, (y - height / 2, height), facecolors=color, **kw)


def quality_figure(timeline, cuts: Sequence[Sequence[tuple[float, float]]] | None = None) -> Figure:
    """Data-quality timeline, one panel per log: segment labels (coloured by the mode they name),
    the motion mode of each row from its configuration, the rows kept for the regression, wheel
    slip events and cuts between continuous recordings (dropouts).

    ``timeline``: :func:`agvdyn.figure_data.quality_timeline`, or the :class:`agvdyn.preflight.FileCheck`
    objects with ``cuts``, per file the time intervals (s) between two continuous stretches.
    """
    q = timeline if isinstance(timeline, data.QualityTimeline) else data.quality_timeline(timeline, cuts)
    lanes = ("labels", "mode (configuration)", "rows kept", "wheel slip")
    fig = _new_figure(12.0, 1.75 * max(len(q.logs), 1) + 0.8)
    axes = np.atleast_1d(fig.subplots(max(len(q.logs), 1), 1, squeeze=False)).ravel()
    y = {name: len(lanes) - 1 - i for i, name in enumerate(lanes)}
    for ax, log in zip(axes, q.logs):
        for name, start, end, mode, named in log.labels:
            _bars(ax, y["labels"], [(start, end)], MODE_COLORS.get(mode, MODE_COLORS["none"]), alpha=0.55,
                  edgecolor="white", lw=0.5)
            if named:
                ax.text((start + end) / 2, y["labels"], name, ha="center", va="center", fontsize=6.5, clip_on=True)
        for mode, a, b in log.modes:
            _bars(ax, y["mode (configuration)"], [(a, b)], MODE_COLORS.get(mode, MODE_COLORS["none"]))
        for span in log.kept:
            _bars(ax, y["rows kept"], [span], "0.25")
        _bars(ax, y["wheel slip"], list(log.slip), "#d62728")
        for a, b in log.cuts:
            ax.axvspan(a, b, color="#ff7f0e", alpha=0.35, lw=0)
            ax.axvline((a + b) / 2, color="#ff7f0e", lw=0.8, ls="--")
        ax.set_yticks([y[n] for n in lanes], lanes, fontsize=8)
        ax.set_ylim(-0.6, len(lanes) - 0.4)
        ax.set_xlim(log.t_start, log.t_end)
        ax.tick_params(axis="x", labelsize=7)
        ax.grid(True, axis="x", lw=0.3)
        ax.set_title(log.path, fontsize=9, loc="left")
    axes[-1].set_xlabel("t [s]", fontsize=8)
    handles = [Patch(color=MODE_COLORS[m], label=_MODE_NAMES[m]) for m in MODE_COLORS if m in q.modes_used]
    handles += [Patch(color="0.25", label="rows kept (any coordinate)"), Patch(color="#d62728", label="wheel slip"),
                Patch(color="#ff7f0e", alpha=0.35, label="cut (dropout)")]
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=7, frameon=False)
    fig.suptitle("Motion modes from the configuration next to the labels, rows kept, slip", fontsize=10)
    return fig


def mode_name(label: str) -> str:
    """``"2s"`` -> ``"2s straight"``: a mode label with its name, as in the figures' legends."""
    return _MODE_NAMES.get(label, str(label))

