"""Figures of the report: Fig. 5 (identification fit), Fig. 6 (validation), parameters against a
reference, parameter correlation, residuals with their autocorrelation, and the data-quality
timeline of each log.

Every function takes a result object and returns a :class:`matplotlib.figure.Figure` built
without pyplot (no global state, works headless with the Agg canvas).

Model torques are drawn only on the rows the fit keeps (``EquationBlock.keep``: stiction rows,
slip, filter edges and their guards left out), in Fig. 5 and Fig. 6 alike: at standstill the
tanh Coulomb term of the model switches with the sign of a velocity that is only noise, and
drawing it there shows chatter the fit never used.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from agvdyn.platform import PAPER_PARAMETERS, PAPER_STD, PARAMETER_NAMES

__all__ = ["identification_figure", "validation_figure", "parameter_figure", "correlation_figure",
           "residual_figure", "quality_figure", "residual_autocorrelation", "mode_name", "MODE_COLORS"]

#: Most points drawn per line (longer signals are decimated for drawing only).
MAX_POINTS = 4000
#: A time step longer than this many median steps breaks a drawn line (dropouts, other runs).
BREAK_STEPS = 3.0

_UNITS = {"alpha_l": "N m", "alpha_r": "N m", "alpha_v": "N m", "gamma_ch": "N m", "x_ch": "N", "y_ch": "N"}
_SYMBOLS = {"alpha_l": r"$\alpha_l$", "alpha_r": r"$\alpha_r$", "alpha_v": r"$\alpha_v$",
            "gamma_ch": r"$\gamma_{ch}$", "x_ch": r"$x_{ch}$", "y_ch": r"$y_{ch}$"}
_COORDINATE_ORDER = ("alpha_l", "alpha_r", "alpha_v", "x_ch", "y_ch", "gamma_ch")

#: One colour per motion mode label (and "none" for rows in no mode), shared by all figures.
MODE_COLORS = {"1": "#4c72b0", "2": "#dd8452", "2s": "#55a868", "3": "#8172b3", "4": "#c44e52", "none": "#b0b0b0"}
_MODE_NAMES = {"1": "1 wheel alignment", "2": "2 car-like", "2s": "2s straight", "3": "3 lateral",
               "4": "4 rotation", "none": "no mode"}
#: Mode each segment label names (PLATFORM.md), for colouring the label lane.
_LABEL_MODE = {"steer_left": "1", "steer_right": "1", "align": "1", "straight": "2s", "rotation": "4",
               "lateral": "3", "lane_change": "2"}


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges of the True runs of a boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


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


def _panels(blocks, p, *, offsets=None):
    """(key, coordinate, t, measured, model, kept) per segment and coordinate with kept rows, the
    runs of one segment joined in time order (and per file when there are several)."""
    several = len({b.source for b in blocks}) > 1
    panels: dict[str, list] = {}
    for b in blocks:
        model = b.model_torque(p, offsets)
        for j, coord in enumerate(b.coordinates):
            key = (f"{b.source}: " if several else "") + f"{b.segment}:{coord}"
            entry = panels.setdefault(key, [coord, [], [], [], []])
            entry[1].append(b.t)
            entry[2].append(b.torque[:, j])
            entry[3].append(model[:, j])
            entry[4].append(b.keep[:, j])
    out = []
    for key, (coord, *arrays) in panels.items():
        t, measured, model, kept = (np.concatenate(a) for a in arrays)
        if not kept.any():
            continue  # e.g. the resting side while the other side steers
        order = np.argsort(t, kind="stable")
        out.append((key, coord, t[order], measured[order], model[order], kept[order]))
    return out


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


def _torque_figure(blocks, p, title: str, *, scores: Mapping[str, str] | None = None, offsets=None) -> Figure:
    panels = _panels(blocks, p, offsets=offsets)
    n = max(1, len(panels))
    cols = 1 if n == 1 else 2
    rows = int(np.ceil(n / cols))
    fig = _new_figure(6.0 * cols, 2.3 * rows + 0.7)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, (key, coord, t, measured, model, kept) in zip(axes, panels):
        _draw(ax, t, measured, model, kept)
        head, _, _ = key.rpartition(":")
        label = f"{head}: {_SYMBOLS.get(coord, coord)}"
        if scores and key in scores:
            label += f"   ({scores[key]})"
        ax.set_title(label, fontsize=9)
        ax.set_ylabel(f"generalized torque [{_UNITS.get(coord, '')}]", fontsize=8)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    if panels:
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)
    return fig


def identification_figure(identification) -> Figure:
    """Fig. 5: measured vs model generalized torques of each identification segment; the model
    (with the estimated motor-torque offsets, when any) on the kept rows only."""
    scores = {k: f"residual RMS {v:.3g}" for k, v in identification.residual_rms.items()}
    return _torque_figure(identification.blocks, identification.parameters.to_vector(),
                          "Identification experiment: generalized torques (cf. Fig. 5)",
                          scores=scores, offsets=identification.offset_vector)


def validation_figure(validation) -> Figure:
    """Fig. 6: measured vs predicted generalized torques of the validation log; the prediction is
    drawn on the rows the NRMSE without stiction rows uses (stiction and edge rows shaded)."""
    scores = {k: f"NRMSE {v:.3f}, without stiction {validation.nrmse_moving[k]:.3f}"
              for k, v in validation.nrmse.items()}
    return _torque_figure(validation.blocks, validation.parameters.to_vector(),
                          "Validation experiment: generalized torques (cf. Fig. 6)", scores=scores)


def parameter_figure(identification, reference=PAPER_PARAMETERS, reference_std=PAPER_STD, *,
                     label: str = "Table 2") -> Figure:
    """Relative deviation of each estimated parameter from a reference, with +-3 std bars."""
    names = [n for n in PARAMETER_NAMES if n not in identification.fixed]
    ref = np.array([getattr(reference, n) for n in names])
    est = np.array([getattr(identification.parameters, n) for n in names])
    std = np.array([identification.std.get(n, np.nan) for n in names])
    ref_std = np.array([reference_std.get(n, np.nan) for n in names])
    fig = _new_figure(7.0, 3.0)
    ax = fig.subplots()
    x = np.arange(len(names))
    ax.axhspan(-5, 5, color="C2", alpha=0.12, label="within 5 %")
    ax.errorbar(x - 0.12, 100 * (est / ref - 1), yerr=300 * std / np.abs(ref), fmt="o", color="C0", ms=4,
                capsize=3, label="estimate, +-3 std")
    if np.isfinite(ref_std).any():
        ax.errorbar(x + 0.12, np.zeros_like(ref), yerr=300 * ref_std / np.abs(ref), fmt="none", ecolor="0.6",
                    capsize=3, label=f"{label}, +-3 std")
    ax.axhline(0, color="0.3", lw=0.6)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("deviation from reference [%]", fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", lw=0.3)
    ax.set_title(f"Identified parameters relative to the reference ({label})", fontsize=10)
    return fig


def correlation_figure(identification) -> Figure:
    """Correlation matrix of the estimated parameters as a heatmap (values written in the cells)."""
    names = list(identification.correlation.get("names", []))
    r = np.array(identification.correlation.get("matrix", []), dtype=float).reshape(len(names), len(names))
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
    ax.set_title(f"Correlation of the estimates ({identification.uncertainty.get('method', '')} covariance)",
                 fontsize=10)
    return fig


def residual_autocorrelation(identification, max_lag: int) -> dict[str, tuple[np.ndarray, int]]:
    """Autocorrelation of the residuals ``tau - H_k^T Theta p`` of the kept rows per generalized
    coordinate, lags ``0..max_lag`` samples: ``{coordinate: (acf, rows)}``.

    Pooled over the blocks; within a block only pairs of kept rows count (masked sums), so the
    left-out rows neither add nor break correlation.
    """
    p = identification.parameters.to_vector()
    offsets = identification.offset_vector
    sums: dict[str, list] = {}
    residuals = [(b, b.torque - b.model_torque(p, offsets)) for b in identification.blocks]
    means = {}
    for b, r in residuals:
        for j, coord in enumerate(b.coordinates):
            k = b.keep[:, j]
            s = means.setdefault(coord, [0.0, 0])
            s[0] += float(r[k, j].sum())
            s[1] += int(k.sum())
    for b, r in residuals:
        n = b.t.size
        size = 1 << int(np.ceil(np.log2(max(2 * n, 2))))
        for j, coord in enumerate(b.coordinates):
            k = b.keep[:, j]
            if not k.any():
                continue
            total, count = means[coord]
            x = np.where(k, r[:, j] - total / count, 0.0)
            m = k.astype(float)
            fx, fm = np.fft.rfft(x, size), np.fft.rfft(m, size)
            num = np.fft.irfft(fx * np.conj(fx), size)[: max_lag + 1]
            cnt = np.fft.irfft(fm * np.conj(fm), size)[: max_lag + 1]
            entry = sums.setdefault(coord, [np.zeros(max_lag + 1), np.zeros(max_lag + 1), 0])
            lags = min(max_lag + 1, n)
            entry[0][:lags] += num[:lags]
            entry[1][:lags] += np.rint(cnt[:lags])
            entry[2] += int(k.sum())
    out = {}
    for coord, (num, cnt, rows) in sums.items():
        with np.errstate(invalid="ignore", divide="ignore"):
            cov = np.where(cnt > 0, num / cnt, np.nan)
        out[coord] = (cov / cov[0], rows)
    return out


def residual_figure(identification, *, max_lag_s: float = 1.5) -> Figure:
    """Residuals of the fit over time (left) and their autocorrelation (right), one row per
    generalized coordinate; the HAC bandwidth of the uncertainty, when there is one, is marked."""
    p = identification.parameters.to_vector()
    offsets = identification.offset_vector
    blocks = identification.blocks
    dt = float(np.median(np.concatenate([np.diff(b.t) for b in blocks if b.t.size > 1]))) if blocks else 2e-3
    bandwidth = identification.uncertainty.get("bandwidth_steps")
    max_lag = int(round(max(max_lag_s, 2.0 * (bandwidth or 0) * dt) / dt))
    acf = residual_autocorrelation(identification, max_lag)
    coords = [c for c in _COORDINATE_ORDER if c in acf]
    sources = sorted({b.source for b in blocks})
    fig = _new_figure(12.0, 1.9 * max(len(coords), 1) + 0.6)
    axes = fig.subplots(max(len(coords), 1), 2, squeeze=False, width_ratios=[2.2, 1])
    for row, coord in enumerate(coords):
        ax, ax_acf = axes[row]
        for b in blocks:
            if coord not in b.coordinates:
                continue
            j = b.coordinates.index(coord)
            if not b.keep[:, j].any():
                continue
            r = b.torque[:, j] - b.model_torque(p, offsets)[:, j]
            t, res = _decimated(b.t, np.where(b.keep[:, j], r, np.nan))
            ax.plot(t, res, lw=0.6, color=f"C{sources.index(b.source) % 10}")
        ax.axhline(0, color="0.3", lw=0.5)
        ax.set_ylabel(f"{_SYMBOLS.get(coord, coord)} [{_UNITS.get(coord, '')}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, lw=0.3)
        values, rows = acf[coord]
        lags = np.arange(values.size) * dt
        ax_acf.plot(lags, values, color="C0", lw=1.0)
        band = 1.96 / np.sqrt(max(rows, 1))
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
    if coords:
        axes[-1][0].set_xlabel("t [s]", fontsize=8)
        axes[-1][1].set_xlabel("lag [s]", fontsize=8)
        if len(sources) > 1:
            fig.legend([Patch(color=f"C{i % 10}") for i in range(len(sources))], sources, loc="outside lower center",
                       ncols=min(len(sources), 3), fontsize=7, frameon=False)
    else:
        axes[0][0].set_visible(False)
        axes[0][1].set_visible(False)
    fig.suptitle("Residuals of the identification per generalized coordinate", fontsize=10)
    return fig


def _bars(ax, y: float, spans: Sequence[tuple[float, float]], color, height: float = 0.7, **kw) -> None:
    spans = [(a, max(b - a, 1e-9)) for a, b in spans]
    if spans:
        ax.broken_barh(spans, (y - height / 2, height), facecolors=color, **kw)


def quality_figure(files: Sequence, cuts: Sequence[Sequence[tuple[float, float]]] | None = None) -> Figure:
    """Data-quality timeline, one panel per log: segment labels (coloured by the mode they name),
    the motion mode of each row from its configuration, the rows kept for the regression, wheel
    slip events and cuts between continuous recordings (dropouts).

    ``files``: :class:`agvdyn.preflight.FileCheck` objects; ``cuts``: per file the time intervals
    (s) between two continuous stretches.
    """
    lanes = ("labels", "mode (configuration)", "rows kept", "wheel slip")
    fig = _new_figure(12.0, 1.75 * max(len(files), 1) + 0.8)
    axes = np.atleast_1d(fig.subplots(max(len(files), 1), 1, squeeze=False)).ravel()
    for k, (ax, check) in enumerate(zip(axes, files)):
        summary, rows = check.summary, check.rows
        y = {name: len(lanes) - 1 - i for i, name in enumerate(lanes)}
        for seg in summary.segments:
            color = MODE_COLORS.get(_LABEL_MODE.get(seg.name, "none"), MODE_COLORS["none"])
            _bars(ax, y["labels"], [(seg.t_start, seg.t_end)], color, alpha=0.55, edgecolor="white", lw=0.5)
            if seg.duration > 0.06 * max(summary.duration, 1e-9):
                ax.text((seg.t_start + seg.t_end) / 2, y["labels"], seg.name, ha="center", va="center", fontsize=6.5,
                        clip_on=True)
        for mode, a, b in check.timeline:
            _bars(ax, y["mode (configuration)"], [(a, b)], MODE_COLORS.get(mode, MODE_COLORS["none"]))
        for blk in rows.blocks:
            kept = blk.keep.any(axis=1)
            _bars(ax, y["rows kept"], [(blk.t[a], blk.t[b - 1]) for a, b in _runs(kept)], "0.25")
        _bars(ax, y["wheel slip"], [(e.t_start, e.t_end) for e in rows.slip_events], "#d62728")
        for a, b in (cuts[k] if cuts is not None and k < len(cuts) else ()):
            ax.axvspan(a, b, color="#ff7f0e", alpha=0.35, lw=0)
            ax.axvline((a + b) / 2, color="#ff7f0e", lw=0.8, ls="--")
        ax.set_yticks([y[n] for n in lanes], lanes, fontsize=8)
        ax.set_ylim(-0.6, len(lanes) - 0.4)
        ax.set_xlim(summary.t_start, summary.t_end)
        ax.tick_params(axis="x", labelsize=7)
        ax.grid(True, axis="x", lw=0.3)
        ax.set_title(summary.path or "<log>", fontsize=9, loc="left")
    axes[-1].set_xlabel("t [s]", fontsize=8)
    used = {m for check in files for m, _, _ in check.timeline}
    handles = [Patch(color=MODE_COLORS[m], label=_MODE_NAMES[m]) for m in MODE_COLORS if m in used]
    handles += [Patch(color="0.25", label="rows kept (any coordinate)"), Patch(color="#d62728", label="wheel slip"),
                Patch(color="#ff7f0e", alpha=0.35, label="cut (dropout)")]
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=7, frameon=False)
    fig.suptitle("Motion modes from the configuration next to the labels, rows kept, slip", fontsize=10)
    return fig


def mode_name(label: str) -> str:
    """``"2s"`` -> ``"2s straight"``: a mode label with its name, as in the figures' legends."""
    return _MODE_NAMES.get(label, str(label))

