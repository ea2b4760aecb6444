"""The report's "Payload tracking" section (issue 31): m_ch and C_ch tracked over the logs with their
std, the detected changes and, for simulated logs, the true values. :func:`track_section` takes a
:class:`~agvdyn.online.TrackResult` (``agvdyn report --track``: the identification logs replayed
with the identified parameters), :func:`read_track_table` the table ``agvdyn track --out`` wrote
(``agvdyn report --tracking``); :func:`track_report_figure` draws, :func:`track_html` formats."""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agvdyn.report._format import esc, img, num, table

__all__ = ["TrackEventRow", "TrackSection", "track_section", "read_track_table", "payload_truth_of_logs",
           "tracking_section", "track_report_figure", "track_html"]

#: Columns of a tracking table (``agvdyn track --out``) the section needs.
TABLE_COLUMNS = ("t", "m_ch", "m_ch_std", "C_ch", "C_ch_std", "event")
#: Points of the figure's lines at most (the table is thinned to this, events kept).
POINTS = 4000


@dataclass(frozen=True)
class TrackEventRow:
    """A detected change: parameter, detection time, estimated change time (None: unknown, from a
    table), value and std before and after."""

    parameter: str
    t_detected: float
    t_change: float | None
    before: float
    before_std: float
    after: float
    after_std: float


@dataclass(frozen=True, eq=False)
class TrackSection:
    """What the section shows: ``source`` (how the tracking was made), the time ``t`` (N,) (logs one after
    another), ``estimate`` and ``std`` (N, 2) of (m_ch, C_ch), the events, the start values ``nominal``,
    the true values ``truth`` ((t, m_ch, C_ch) from each simulated pick-up or drop on) and notes."""

    source: str
    t: np.ndarray
    estimate: np.ndarray
    std: np.ndarray
    events: tuple[TrackEventRow, ...]
    nominal: tuple[float, float]
    truth: tuple[tuple[float, float, float], ...] = ()
    notes: tuple[str, ...] = ()


def _continuous_time(t: np.ndarray, source: np.ndarray) -> np.ndarray:
    """Time with each log after the previous one (a log's own clock may start at 0 again)."""
    out = np.asarray(t, dtype=float).copy()
    shift = 0.0
    for s in np.unique(source):
        sel = source == s
        first = float(out[sel][0])
        out[sel] += shift - first if shift > first else 0.0
        shift = float(out[sel][-1]) + (float(np.median(np.diff(out[sel]))) if sel.sum() > 1 else 0.0)
    return out


def track_section(result: Any, *, source: str, truth: Sequence[tuple[float, float, float]] = (),
                  notes: Sequence[str] = ()) -> TrackSection:
    """The section of a :class:`~agvdyn.online.TrackResult`, the lines thinned to about :data:`POINTS`."""
    t = _continuous_time(result.t, result.source)
    shift = {int(s): float(t[result.source == s][0] - result.t[result.source == s][0])
             for s in np.unique(result.source)}
    keep = np.zeros(t.size, dtype=bool)
    keep[::max(1, t.size // POINTS)] = True
    keep[np.flatnonzero(result.event)] = True
    keep[-1] = True
    names = {s: i for i, s in enumerate(result.sources)}
    events = tuple(TrackEventRow(e.parameter, e.t_detected + shift.get(names.get(e.source, 0), 0.0),
                                 e.t_change_estimate + shift.get(names.get(e.source, 0), 0.0), e.before,
                                 e.before_std, e.after, e.after_std) for e in result.events)
    nominal = (float(result.estimate[0, 0]), float(result.estimate[0, 1]))
    return TrackSection(source, t[keep], result.estimate[keep], result.std[keep], events, nominal, tuple(truth),
                        tuple(notes))


def read_track_table(path: str | os.PathLike) -> TrackSection:
    """The section of a tracking table (``agvdyn track --out``, .parquet or .csv); events from its
    ``event`` column (bit 0: m_ch, bit 1: C_ch: value and std of the row before and of the row).
    ValueError naming the file and the column when it is not such a table."""
    import pandas as pd

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".parquet", ".csv"):
        raise ValueError(f"{path}: unknown suffix {path.suffix!r}: expected a tracking table (.parquet or .csv)")
    frame = pd.read_parquet(path) if suffix == ".parquet" else pd.read_csv(path)
    missing = [c for c in TABLE_COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"{path}: columns {missing} missing: expected a tracking table of `agvdyn track` with "
                         f"{list(TABLE_COLUMNS)}")
    data = {c: frame[c].to_numpy(dtype=float) for c in TABLE_COLUMNS}
    bad = [c for c in TABLE_COLUMNS if not np.all(np.isfinite(data[c]))]
    if bad or frame.empty:
        raise ValueError(f"{path}: column {bad[0] if bad else 't'}: expected finite numbers in every row")
    estimate = np.column_stack([data["m_ch"], data["C_ch"]])
    std = np.column_stack([data["m_ch_std"], data["C_ch_std"]])
    flags = data["event"].astype(np.int64)
    events = []
    for k in np.flatnonzero(flags):
        for i, name in enumerate(("m_ch", "C_ch")):
            if flags[k] & (1 << i):
                j = max(k - 1, 0)
                events.append(TrackEventRow(name, float(data["t"][k]), None, float(estimate[j, i]), float(std[j, i]),
                                            float(estimate[k, i]), float(std[k, i])))
    return TrackSection(f"tracking table {path}", data["t"], estimate, std, tuple(events),
                        (float(estimate[0, 0]), float(estimate[0, 1])))


def payload_truth_of_logs(logs: Sequence[Any]) -> tuple[tuple[float, float, float], ...]:
    """(t, m_ch, C_ch) of each simulated pick-up or drop (sidecar ``payload_truth``), logs one after
    another as :func:`_continuous_time` puts them; empty for logs without one."""
    from agvdyn.io.log import sidecar_value

    out, shift = [], 0.0
    for log in logs:
        t = np.asarray(log.t, dtype=float)
        offset = shift - float(t[0]) if shift > float(t[0]) else 0.0
        for entry in sidecar_value(log, "payload_truth", None) or []:
            try:
                out.append((float(entry["t_applied"]) + offset, float(entry["m_ch"]), float(entry["C_ch"])))
            except (KeyError, TypeError, ValueError):
                continue
        shift = float(t[-1]) + offset + (float(np.median(np.diff(t))) if t.size > 1 else 0.0)
    return tuple(out)


def tracking_section(logs: Sequence[Any], geometry: Any, identification: Any, track: bool,
                     tracking: Any) -> TrackSection | None:
    """The report's section (:func:`agvdyn.report.make_report`): of ``tracking`` when given (a section,
    a :class:`~agvdyn.online.TrackResult` or a table's path), else of the logs replayed with the
    identified parameters when ``track`` (and identified), else None."""
    if tracking is not None:
        if isinstance(tracking, TrackSection):
            return tracking
        if isinstance(tracking, (str, os.PathLike)):
            return read_track_table(tracking)
        return track_section(tracking, source="a tracking result (agvdyn.online.track)")
    if not track or identification is None or not logs:
        return None
    from agvdyn.online import track as replay

    result = replay(list(logs), geometry, identification.parameters, std=dict(identification.std))
    return track_section(result, source="the identification logs replayed with the identified parameters "
                                        "(agvdyn.online.track; every parameter but m_ch and C_ch held)",
                         truth=payload_truth_of_logs(logs))


def track_report_figure(section: TrackSection):
    """m_ch and C_ch over time with a band of +-2 std, the detected changes (vertical lines) and the
    true values when known."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 5.6), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    colors = {"m_ch": "tab:red", "C_ch": "tab:purple"}
    for i, (ax, name, unit) in enumerate(zip(axes, ("m_ch", "C_ch"), ("kg", "kg m^2"))):
        value, std = section.estimate[:, i], section.std[:, i]
        ax.fill_between(section.t, value - 2 * std, value + 2 * std, color="tab:blue", alpha=0.18, lw=0,
                        label="+-2 std")
        ax.plot(section.t, value, color="tab:blue", lw=1.3, label=f"{name} tracked")
        if section.truth:  # from the first simulated pick-up or drop on (before it: not in the sidecar)
            times = [s[0] for s in section.truth] + [max(float(section.t[-1]), section.truth[-1][0])]
            values = [s[1 + i] for s in section.truth]
            ax.step(times, values + [values[-1]], where="post", color="black", ls=":", lw=1.2, label=f"{name} true")
        for e in section.events:
            ax.axvline(e.t_detected, color=colors[e.parameter], ls="--", lw=1,
                       label=f"{e.parameter} change detected")
        handles, labels = ax.get_legend_handles_labels()
        unique = dict(zip(labels, handles))
        ax.legend(unique.values(), unique.keys(), fontsize=8, loc="upper left", ncol=4)
        spread = float(np.nanmax(value) - np.nanmin(value)) or abs(float(value[0])) * 0.05
        ax.set_ylim(float(np.nanmin(value)) - 0.6 * spread, float(np.nanmax(value)) + 0.6 * spread)
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].set_title("Payload tracking: tracked parameters and detected changes")
    axes[1].set_xlabel("t (s)")
    return fig


def track_html(section: TrackSection | None) -> str:
    """The "Payload tracking" section: facts, figure and the detected changes; nothing without a section."""
    if section is None:
        return ""
    s = section
    facts = [["tracking", esc(s.source)],
             ["start", f"m_ch {num(s.nominal[0], 5)} kg, C_ch {num(s.nominal[1], 4)} kg&nbsp;m<sup>2</sup>"],
             ["end", f"m_ch {num(s.estimate[-1, 0], 5)} &plusmn; {num(s.std[-1, 0], 2)} kg, C_ch "
                     f"{num(s.estimate[-1, 1], 4)} &plusmn; {num(s.std[-1, 1], 2)} kg&nbsp;m<sup>2</sup>"],
             ["changes detected", str(len(s.events))]]
    if s.truth:
        facts.append(["true (simulated)", "; ".join(f"from {num(t, 4)}&nbsp;s: m_ch {num(m, 5)}, C_ch {num(c, 4)}"
                                                    for t, m, c in s.truth)])
    parts = ['<section id="tracking"><h2>Payload tracking</h2>', table(None, facts, align="ll"),
             img(track_report_figure(s), "Tracked m_ch and C_ch (+-2 std), detected changes (dashed) and, when "
                                         "simulated, the true values (dotted).")]
    if s.events:
        rows = [[esc(e.parameter), num(e.t_detected, 5), num(e.t_change, 5) if e.t_change is not None else "&ndash;",
                 f"{num(e.before, 5)} &plusmn; {num(e.before_std, 2)}",
                 f"{num(e.after, 5)} &plusmn; {num(e.after_std, 2)}"] for e in s.events]
        parts.append(table(["parameter", "detected (s)", "change estimated (s)", "before", "after"], rows, align="l"))
    parts += [f'<p class="note">{esc(n)}</p>' for n in s.notes]
    parts.append("</section>")
    return "".join(parts)
