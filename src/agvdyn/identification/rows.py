"""Stage 2 of the row pipeline: which rows of a filtered stretch are used, and as what.

Every row's motion mode comes from its configuration (eq. 9, PLATFORM.md) and its velocities:

* chassis at rest (wheel surface speed not explained by steering below ``rest_speed``) with the
  steering moving: wheel alignment at rest, mode 1, whatever the angles;
* chassis at rest otherwise: the mode of the configuration (its chassis rows are stiction rows);
* chassis moving: the mode of the configuration; the straight configuration with the steering
  moving along the ICR relation is car-like motion (mode 2); moving in no mode's configuration
  (mode 1's angles, or the straight configuration steered off the ICR relation), or steering while
  moving laterally or rotating, is no mode of the model: left out and counted.

A segment label is a hint: it names the rows' experiment (block names, ``--segments``), and a
label that disagrees with the row's mode is counted, never a refusal. Rows inside the filter's
transient at a stretch's ends, wheel-slip rows and their guard, and rows of unselected segments
are dropped; stiction rows (sec. 7) and a guard around them and around mode changes too.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from agvdyn.identification.equations import EquationBlock, projected_block
from agvdyn.identification.settings import IdentificationSettings
from agvdyn.identification.slip import SlipEvent, slip_rows, slip_threshold
from agvdyn.identification.stretches import Stretch, filtered_stretch, log_source, min_stretch_rows, stretch_bounds
from agvdyn.kinematics import Mode, detect_mode, icr_residual, kinematic_model
from agvdyn.platform import Geometry
from agvdyn.signals import guarded_mask, row_max_abs, runs

__all__ = ["LABEL_MODES", "RowCounts", "LogRows", "row_modes", "log_rows", "log_equations", "labels_present"]

#: Motion mode of the rows each segment label names (PLATFORM.md); only for counting disagreements.
LABEL_MODES: dict[str, tuple[Mode, ...]] = {
    "steer_left": (Mode.PARKING,), "steer_right": (Mode.PARKING,), "align": (Mode.PARKING,),
    "straight": (Mode.STRAIGHT,), "rotation": (Mode.ROTATION,), "lateral": (Mode.LATERAL,),
    "lane_change": (Mode.CAR_LIKE, Mode.STRAIGHT),
}
NO_MODE = 0


@dataclass
class RowCounts:
    """What happened to the samples of the logs (counts of samples, not of equation rows)."""

    samples: int = 0
    stretches: int = 0
    edge: int = 0
    too_short: int = 0
    no_mode: int = 0
    not_selected: int = 0
    slip: int = 0
    used: int = 0
    per_mode: dict[str, int] = field(default_factory=dict)
    label_mismatch: dict[str, int] = field(default_factory=dict)
    clipped_stop: dict[str, int] = field(default_factory=dict)

    def add(self, other: "RowCounts") -> None:
        for key in ("samples", "stretches", "edge", "too_short", "no_mode", "not_selected", "slip", "used"):
            setattr(self, key, getattr(self, key) + getattr(other, key))
        for key in ("per_mode", "label_mismatch", "clipped_stop"):
            mine = getattr(self, key)
            for k, v in getattr(other, key).items():
                mine[k] = mine.get(k, 0) + v

    def to_dict(self) -> dict[str, Any]:
        return {"samples": self.samples, "stretches": self.stretches, "dropped_edge": self.edge,
                "dropped_too_short": self.too_short, "dropped_no_mode": self.no_mode,
                "dropped_not_selected": self.not_selected, "dropped_slip": self.slip, "used": self.used,
                "per_mode": dict(self.per_mode), "label_mismatch": dict(self.label_mismatch),
                "clipped_stop": dict(self.clipped_stop)}


@dataclass(frozen=True, eq=False)
class LogRows:
    """The equation blocks of one log and the account of its rows."""

    source: str
    blocks: tuple[EquationBlock, ...]
    counts: RowCounts
    slip_events: tuple[SlipEvent, ...]
    slip_threshold: float
    notes: tuple[str, ...]
    modes: np.ndarray  # (N,) mode per sample (0: no mode, or not filtered)


def row_modes(geometry: Geometry, st: Stretch, settings: IdentificationSettings) -> np.ndarray:
    """Motion mode of each row of a filtered stretch (Mode values; 0 = in no mode of the model)."""
    config = detect_mode(geometry, st.alpha, settings.mode_tolerance).astype(np.int8)
    H1 = kinematic_model(geometry, Mode.PARKING, st.alpha[:1])[0]
    rolling = st.beta_dot - st.alpha_dot @ H1[5:].T  # wheel rates not explained by steering at rest
    rest = row_max_abs(rolling) * geometry.r < settings.rest_speed
    steering = row_max_abs(st.alpha_dot) > settings.steering_rest_rate
    mode = config.copy()
    mode[rest & steering] = int(Mode.PARKING)
    moving = ~rest
    mode[moving & (config == int(Mode.PARKING))] = NO_MODE
    moving_steered = moving & steering
    straight_steered = np.flatnonzero(moving_steered & (config == int(Mode.STRAIGHT)))
    if straight_steered.size:  # car-like through alpha_v = 0 when the ICR relation holds
        on_icr = np.abs(icr_residual(geometry, st.alpha[straight_steered])) <= settings.mode_tolerance
        mode[straight_steered] = np.where(on_icr, int(Mode.CAR_LIKE), NO_MODE)
    mode[moving_steered & ((config == int(Mode.LATERAL)) | (config == int(Mode.ROTATION)))] = NO_MODE
    return mode


@dataclass(frozen=True)
class _Labels:
    """Segment labels as integer codes into ``names`` (``""``: no label)."""

    names: tuple[str, ...]
    codes: np.ndarray

    @classmethod
    def of(cls, log: Any) -> "_Labels | None":
        frame = getattr(log, "frame", None)
        column = None if frame is None or "segment" not in frame.columns else frame["segment"]
        if column is not None and isinstance(column.dtype, pd.CategoricalDtype):  # our logs: no string pass
            names = ("", *(str(c) for c in column.cat.categories))
            return cls(names, column.cat.codes.to_numpy().astype(np.int32) + 1)
        seg = getattr(log, "segments", None)
        if seg is None:
            return None
        names, codes = np.unique(np.asarray(seg).astype(str), return_inverse=True)
        return cls(tuple(str(n) for n in names), codes.astype(np.int32))

    def selected(self, wanted: tuple[str, ...], sl: slice) -> np.ndarray:
        return np.isin(self.codes[sl], [i for i, n in enumerate(self.names) if n in wanted])


def labels_present(log: Any) -> set[str]:
    """The segment labels a log carries (empty without a segment column)."""
    labels = _Labels.of(log)
    if labels is None:
        return set()
    counts = np.bincount(labels.codes, minlength=len(labels.names))
    return {n for n, c in zip(labels.names, counts) if c and n}


def _count_mismatch(counts: RowCounts, labels: _Labels, sl: slice, mode: np.ndarray) -> None:
    codes = labels.codes[sl]
    for code, name in enumerate(labels.names):
        expected = LABEL_MODES.get(name)
        if expected is None:
            continue
        rows = codes == code
        if rows.any():
            ok = np.zeros_like(rows)
            for m in expected:
                ok |= mode == int(m)
            off = int(np.count_nonzero(rows & ~ok))
            if off:
                counts.label_mismatch[name] = counts.label_mismatch.get(name, 0) + off


def _stretch_blocks(geometry: Geometry, st: Stretch, mode: np.ndarray, usable: np.ndarray, labels: _Labels | None,
                    settings: IdentificationSettings, recording: str, mine: np.ndarray) -> list[EquationBlock]:
    """Blocks of one stretch: a run of one mode is projected at once (stiction guard at its ends),
    then split where the label changes (block names only: no filter starts there)."""
    guard = int(round(settings.seconds(settings.stiction_guard) / st.dt))
    thresholds = settings.thresholds()
    q_dot = st.q_dot
    blocks = []
    for a, b in runs(mode):
        if mode[a] == NO_MODE or not (usable[a:b] & mine[a:b]).any():
            continue
        m = Mode(int(mode[a]))
        block = projected_block(geometry, m, st.alpha[a:b], q_dot[a:b], st.signals[a:b], st.torque[a:b],
                                t=st.t[a:b], source=st.source, segment=f"mode {m.label}",
                                stiction_threshold=thresholds, mode_tolerance=settings.mode_tolerance,
                                recording=recording, sample=np.arange(st.rows.start + a, st.rows.start + b))
        block = block.with_keep(guarded_mask(block.keep & usable[a:b, None], guard) & mine[a:b, None])
        if labels is None:
            blocks.append(block)
            continue
        codes = labels.codes[st.rows][a:b]
        for c, d in runs(codes):
            blocks.append(block.rows(slice(c, d), labels.names[codes[c]] or f"mode {m.label}"))
    return blocks


def log_rows(log: Any, geometry: Geometry, settings: IdentificationSettings = IdentificationSettings(),
             core: slice | None = None) -> LogRows:
    """Equation blocks of a log: stretches filtered once, rows classified, slip and stiction dropped.

    ``core``: for a piece of a longer log (:func:`agvdyn.io.chunks.log_pieces`), the rows that are
    its own; the others (its neighbours' overlap) are filtered but neither used nor counted.
    """
    source = log_source(log)
    t, alpha, beta = log.t, log.alpha, log.beta
    labels = _Labels.of(log)
    own = np.ones(t.size, dtype=bool)
    if core is not None:
        own[:] = False
        own[core] = True
    counts = RowCounts(samples=int(own.sum()), clipped_stop={k: int(v) for k, v in getattr(log, "clipped", {}).items()})
    bounds, notes = stretch_bounds(t, alpha, beta, settings)
    notes = [f"{source}: {n}" for n in notes]
    min_rows = min_stretch_rows(settings, float(np.median(np.diff(t))))
    stretches, modes = [], np.zeros(t.size, dtype=np.int8)
    for a, b in bounds:
        if b - a <= min_rows:
            counts.too_short += int(own[a:b].sum())
            notes.append(f"{source}: rows {a}..{b - 1} ({b - a} samples) skipped: a continuous stretch needs more "
                         f"than {min_rows} samples for the zero-phase filter and its edges")
            continue
        st = filtered_stretch(geometry, log, a, b, settings)
        stretches.append(st)
        modes[a:b] = row_modes(geometry, st, settings)
    counts.stretches = len(stretches)
    in_mode = [(st, modes[st.rows]) for st in stretches]
    speeds = np.concatenate([row_max_abs(st.slip)[(m != NO_MODE) & ~st.edge] for st, m in in_mode] or [np.zeros(0)])
    threshold = slip_threshold(speeds, settings)
    slip_guard = settings.slip_guard
    blocks, events = [], []
    for k, (st, mode) in enumerate(in_mode):
        drop_slip, ev = slip_rows(source, st.t, st.slip, threshold, int(round(slip_guard / st.dt)))
        if core is not None:  # an event belongs to the piece where it starts
            ev = [e for e in ev if t[core.start] <= e.t_start <= t[core.stop - 1]]
        events += ev
        if settings.segments is None:
            selected = np.ones(st.n, dtype=bool)
        else:
            selected = np.zeros(st.n, dtype=bool) if labels is None else labels.selected(settings.segments, st.rows)
        in_a_mode = mode != NO_MODE
        mine = own[st.rows]  # the guards see the neighbours' rows; only the piece's own are used and counted
        counts.edge += int(np.count_nonzero(st.edge & mine))
        rest = ~st.edge
        counts.no_mode += int(np.count_nonzero(rest & ~in_a_mode & mine))
        rest &= in_a_mode
        counts.not_selected += int(np.count_nonzero(rest & ~selected & mine))
        rest &= selected
        counts.slip += int(np.count_nonzero(rest & drop_slip & mine))
        usable = rest & ~drop_slip
        counts.used += int(np.count_nonzero(usable & mine))
        for m in np.unique(mode[usable & mine]):
            label = Mode(int(m)).label
            counts.per_mode[label] = counts.per_mode.get(label, 0) + int(np.count_nonzero(usable & mine & (mode == m)))
        if labels is not None:
            _count_mismatch(counts, labels, st.rows, mode)
        blocks += _stretch_blocks(geometry, st, mode, usable, labels, settings, f"{source}#{k}", mine)
    return LogRows(source, tuple(blocks), counts, tuple(events), threshold, tuple(notes), modes)


def log_equations(log: Any, geometry: Geometry, settings: IdentificationSettings = IdentificationSettings()
                  ) -> tuple[list[EquationBlock], list[str]]:
    """Equation blocks of every usable row of a log and notes (see :func:`log_rows`)."""
    rows = log_rows(log, geometry, settings)
    return list(rows.blocks), list(rows.notes)
