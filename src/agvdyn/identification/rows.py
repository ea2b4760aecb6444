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

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from agvdyn._lazy import pandas as pd

from agvdyn.identification._kernels import stretch_modes, stretch_projection
from agvdyn.io.schema import SEGMENTS, LazyFrame
from agvdyn.identification.account import LogRows, RowCounts
from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.model_rows import model_projection_columns, resolved_model, stribeck_support
from agvdyn.identification.settings import IdentificationSettings
from agvdyn.identification.slip import slip_rows, slip_threshold
from agvdyn.identification.stretches import Stretch, filtered_stretch, log_source, min_stretch_rows, stretches_of
from agvdyn.identification.workspace import Workspace, empty
from agvdyn.kinematics import Mode, max_virtual_angle, nominal_steering
from agvdyn.kinematics.models import _constant_model
from agvdyn.model_spec import PAPER_MODEL, ModelSpec
from agvdyn.platform import Geometry
from agvdyn.row_rules import RowSettings
from agvdyn.segments_vocabulary import label_modes
from agvdyn.signals import row_max_abs

__all__ = ["LABEL_MODES", "RowCounts", "LogRows", "row_modes", "log_rows", "log_equations", "labels_present"]

#: Motion modes of the rows each segment label names (:mod:`agvdyn.segments_vocabulary`); only for
#: counting disagreements.
LABEL_MODES: dict[str, tuple[Mode, ...]] = {name: tuple(Mode.from_label(m) for m in modes)
                                             for name, modes in label_modes().items()}
NO_MODE = 0


@dataclass(frozen=True, eq=False)
class _ModeTables:
    """Constants of the compiled mode and projection kernels, indexed by Mode value (0: none):
    ``h`` (6, 9, 2) constant H_k, ``pinv`` (6, 2, 9) their pseudo-inverses, ``dof`` (6,),
    ``thresholds`` (6, 2) stiction thresholds of the coordinates, ``nominal`` (3, 2) steering of
    straight, rotation and lateral, ``h1`` (4, 2) wheel rows of H_1, ``offsets`` (6, 2, 4) ``H_k^T B e_i``."""

    h: np.ndarray
    pinv: np.ndarray
    dof: np.ndarray
    thresholds: np.ndarray
    nominal: np.ndarray
    h1: np.ndarray
    offsets: np.ndarray


@functools.lru_cache(maxsize=16)
def _mode_tables(geometry: Geometry, thresholds: tuple[tuple[str, float], ...]) -> _ModeTables:
    limits = dict(thresholds)
    h, pinv = np.zeros((6, 9, 2)), np.zeros((6, 2, 9))
    dof, thr, offsets = np.zeros(6, dtype=np.int64), np.zeros((6, 2)), np.zeros((6, 2, 4))
    for m in Mode:
        dof[m] = m.dof
        thr[m, :m.dof] = [limits[c] for c in m.coordinates]
        if m is Mode.CAR_LIKE:
            continue
        H = _constant_model(geometry, m)
        h[m, :, :m.dof] = H
        pinv[m, :m.dof] = np.linalg.pinv(H)
        offsets[m, :m.dof] = geometry.i_G * H[5:, :].T
    nominal = np.array([nominal_steering(geometry, m) for m in (Mode.STRAIGHT, Mode.ROTATION, Mode.LATERAL)])
    return _ModeTables(h, pinv, dof, thr, nominal, np.ascontiguousarray(h[Mode.PARKING, 5:, :]), offsets)


@functools.lru_cache(maxsize=32)
def _guard_samples(rules: RowSettings, dt: float) -> np.ndarray:
    """(6, 2) stiction guard in samples of each mode's coordinate slots (read-only;
    :meth:`~agvdyn.row_rules.RowSettings.guard_samples`, as the planner's)."""
    guards = rules.guards()
    out = np.zeros((6, 2), dtype=np.int64)
    for m in Mode:
        out[m, :m.dof] = [rules.guard_samples(guards[c], dt) for c in m.coordinates]
    out.flags.writeable = False
    return out


def _tables(geometry: Geometry, settings: IdentificationSettings) -> _ModeTables:
    return _mode_tables(geometry, tuple(sorted(settings.rows.thresholds().items())))


def _modes_and_virtual_angle(geometry: Geometry, st: Stretch, settings: IdentificationSettings
                             ) -> tuple[np.ndarray, np.ndarray]:
    tables = _tables(geometry, settings)
    mode, av = np.empty(st.n, dtype=np.int8), np.zeros(st.n)
    stretch_modes(st.alpha, st.trig, st.q_dot, geometry.b / geometry.l, max_virtual_angle(geometry),
                  float(settings.rows.mode_tolerance), tables.nominal, tables.h1, geometry.r,
                  float(settings.rows.rest_speed), float(settings.rows.steering_rest_rate), mode, av)
    return mode, av


def row_modes(geometry: Geometry, st: Stretch, settings: IdentificationSettings) -> np.ndarray:
    """Motion mode of each row of a filtered stretch (Mode values; 0 = in no mode of the model),
    by the rules of the module docstring (compiled: :func:`._kernels.stretch_modes`)."""
    return _modes_and_virtual_angle(geometry, st, settings)[0]


@dataclass(frozen=True)
class _Labels:
    """Segment labels as integer codes into ``names`` (``""``: no label)."""

    names: tuple[str, ...]
    codes: np.ndarray

    @classmethod
    def of(cls, log: Any) -> "_Labels | None":
        """The labels of a log (kept on an agvdyn.io.Log: its frame is read only)."""
        cache = getattr(log, "__dict__", None)
        if cache is not None and "_labels" in cache:
            return cache["_labels"]
        labels = cls._of(log)
        if cache is not None and "frame" in cache:
            cache["_labels"] = labels
        return labels

    @classmethod
    def _of(cls, log: Any) -> "_Labels | None":
        raw = getattr(log, "__dict__", {}).get("frame")
        if isinstance(raw, LazyFrame):  # read by read_log: codes into SEGMENTS, no DataFrame needed
            if raw.segment_codes is None:
                return None
            return cls(("", *SEGMENTS), raw.segment_codes.astype(np.int32) + 1)
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
    return set() if labels is None else _present(labels)


def _present(labels: _Labels) -> set[str]:
    counts = np.bincount(labels.codes, minlength=len(labels.names))
    return {n for n, c in zip(labels.names, counts) if c and n}


def _count_mismatch(counts: RowCounts, labels: _Labels, sl: slice, mode: np.ndarray) -> None:
    """Rows whose label names an experiment of other modes than the row's, per label."""
    width = len(Mode) + 1
    table = np.bincount(labels.codes[sl] * width + mode, minlength=len(labels.names) * width).reshape(-1, width)
    for code, name in enumerate(labels.names):
        expected = LABEL_MODES.get(name)
        if expected is None:
            continue
        off = int(table[code].sum() - sum(int(table[code, int(m)]) for m in expected))
        if off:
            counts.label_mismatch[name] = counts.label_mismatch.get(name, 0) + off


def _stretch_blocks(geometry: Geometry, st: Stretch, mode: np.ndarray, av: np.ndarray, usable: np.ndarray,
                    labels: _Labels | None, settings: IdentificationSettings, recording: str, mine: np.ndarray,
                    workspace: Workspace | None = None, tag: str = "", model: ModelSpec = PAPER_MODEL
                    ) -> list[EquationBlock]:
    """Blocks of one stretch: a run of one mode is projected at once (stiction guard at its ends),
    then split where the label changes (block names only: no filter starts there). The rows of all
    runs come from one compiled pass (:func:`._kernels.stretch_projection`); blocks are views. A
    ``model`` with columns of its own (``linear_names``) adds them to each block (:mod:`.model_rows`)."""
    guards = _guard_samples(settings.rows, float(st.dt))
    tables = _tables(geometry, settings)
    n = st.n
    Y, tau = empty(workspace, f"Y{tag}", (n, 2, 11)), empty(workspace, f"tau{tag}", (n, 2))
    s_dot, keep = empty(workspace, f"s_dot{tag}", (n, 2)), empty(workspace, f"keep{tag}", (n, 2), bool)
    offsets = empty(workspace, f"offsets{tag}", (n, 2, 4))
    runs_found = empty(workspace, f"runs{tag}", (n, 2), np.int64)
    count = stretch_projection(mode, av, st.q_dot, st.signals, st.torque, tables.h, tables.pinv, tables.dof, tables.thresholds,
                               usable, mine, guards, geometry.l, geometry.b, geometry.a, geometry.r,
                               max_virtual_angle(geometry), geometry.i_G, Y, tau, s_dot, keep, offsets, runs_found)
    X = None
    if model.linear_names:
        X = empty(workspace, f"model{tag}", (n, 2, len(model.linear_names)))
        model_projection_columns(model, mode, av, runs_found, count, st.signals, st.extra, tables.h, tables.dof,
                                 geometry, max_virtual_angle(geometry), Y, X)
    blocks = []
    sample = np.arange(st.rows.start, st.rows.start + n)
    codes = None if labels is None else labels.codes[st.rows]
    changes = None if codes is None else np.flatnonzero(codes[1:] != codes[:-1]) + 1  # label changes, once
    constant: dict[Mode, np.ndarray] = {}
    for a, b in runs_found[:count].tolist():
        m = Mode(int(mode[a]))
        k = m.dof
        if m is Mode.CAR_LIKE:
            offs = offsets[:, :k]
        else:
            offs = constant.get(m)
            if offs is None:  # once per mode (setdefault would build it for every run)
                offs = constant[m] = np.broadcast_to(tables.offsets[m, :k], (n, k, 4))
        cuts = [a, b] if changes is None else [a, *changes[np.searchsorted(changes, a, "right"):
                                                            np.searchsorted(changes, b, "left")].tolist(), b]
        for c, d in zip(cuts, cuts[1:]):  # a run split where the label changes (block names only)
            name = f"mode {m.label}" if codes is None else labels.names[codes[c]] or f"mode {m.label}"
            blocks.append(EquationBlock(st.source, name, m, st.t[c:d], Y[c:d, :k], tau[c:d, :k], s_dot[c:d, :k],
                                        keep[c:d, :k], offs[c:d], recording, sample[c:d],
                                        None if X is None else X[c:d, :k]))
    return blocks


def log_rows(log: Any, geometry: Geometry, settings: IdentificationSettings = IdentificationSettings(),
             core: slice | None = None, workspace: Workspace | None = None, model: ModelSpec = PAPER_MODEL
             ) -> LogRows:
    """The row pass of a log: stretches filtered once, rows classified, slip and stiction dropped,
    the rows kept as equation blocks and their account (:class:`LogRows`). Every consumer
    (:func:`~agvdyn.identification.identify`, :func:`agvdyn.preflight.preflight`, the report's
    cuts) reads this one result: a log is passed once.

    ``core``: for a piece of a longer log (:func:`agvdyn.io.chunks.log_pieces`), the rows that are
    its own; the others (its neighbours' overlap) are filtered but neither used nor counted.
    ``workspace``: buffers reused from the previous log; the blocks are then views valid only
    until the next log that uses it (see :mod:`.workspace`). ``model``: a resolved
    :class:`~agvdyn.model_spec.ModelSpec` whose extensions the rows carry (:mod:`.model_rows`).
    """
    model = resolved_model(model)
    source = log_source(log)
    t = log.t
    labels = _Labels.of(log)
    own = np.ones(t.size, dtype=bool)
    if core is not None:
        own[:] = False
        own[core] = True
    counts = RowCounts(samples=int(own.sum()), clipped_stop={k: int(v) for k, v in getattr(log, "clipped", {}).items()})
    bounds, cuts, nominal = stretches_of(t, log.alpha, log.beta, settings, getattr(log, "sample_time", None))
    notes = [f"{source}: {n}" for n in cuts]
    stretches, modes = _classified_stretches(log, geometry, settings, bounds, nominal, own, counts, notes, workspace,
                                             model)
    peaks = [row_max_abs(st.slip) for st, _ in stretches]
    speeds = np.concatenate([p[(modes[st.rows] != NO_MODE) & ~st.edge] for p, (st, _) in zip(peaks, stretches)]
                            or [np.zeros(0)])
    threshold = slip_threshold(speeds, settings)
    blocks, events = [], []
    for k, (st, av) in enumerate(stretches):
        drop_slip, ev = slip_rows(source, st.t, st.slip, threshold, int(round(settings.rows.slip_guard / st.dt)),
                                  peaks[k])
        if core is not None:  # an event belongs to the piece where it starts
            ev = [e for e in ev if t[core.start] <= e.t_start <= t[core.stop - 1]]
        events += ev
        usable = _usable_rows(st, modes[st.rows], drop_slip, labels, settings, own[st.rows], counts)
        made = _stretch_blocks(geometry, st, modes[st.rows], av, usable, labels, settings, f"{source}#{k}",
                               own[st.rows], workspace, f"#{k}", model)
        for g, c in stribeck_support(model, st.q_dot, st.rows.start, made).items():
            counts.stribeck_support[g] = counts.stribeck_support.get(g, 0) + c
        blocks += made
    gaps = tuple((float(t[b - 1]), float(t[c])) for (_, b), (c, _) in zip(bounds[:-1], bounds[1:]))
    present = frozenset() if labels is None else frozenset(_present(labels))
    return LogRows(source, tuple(blocks), counts, tuple(events), threshold, tuple(notes), modes, tuple(cuts), gaps,
                   present)


def _classified_stretches(log: Any, geometry: Geometry, settings: IdentificationSettings,
                          bounds: list[tuple[int, int]], nominal: float, own: np.ndarray, counts: RowCounts,
                          notes: list[str], workspace: Workspace | None, model: ModelSpec = PAPER_MODEL
                          ) -> tuple[list[tuple[Stretch, np.ndarray]], np.ndarray]:
    """Each stretch long enough filtered once and its rows' modes (the others counted and noted):
    ``[(stretch, virtual angle)]`` and the mode of every sample of the log (0: none)."""
    source, size = log_source(log), log.t.size
    min_rows = min_stretch_rows(settings, nominal)
    stretches, modes = [], np.zeros(size, dtype=np.int8)
    for a, b in bounds:
        if b - a <= min_rows:
            counts.too_short += int(own[a:b].sum())
            notes.append(f"{source}: rows {a}..{b - 1} ({b - a} samples) skipped: a continuous stretch needs more "
                         f"than {min_rows} samples for the zero-phase filter and its edges")
            continue
        st = filtered_stretch(geometry, log, a, b, settings, workspace, f"#{len(stretches)}",
                              nominal if (a, b) == (0, size) else None, model)  # one stretch: the log's median step
        mode, av = _modes_and_virtual_angle(geometry, st, settings)
        stretches.append((st, av))
        modes[a:b] = mode
    counts.stretches = len(stretches)
    return stretches, modes


def _usable_rows(st: Stretch, mode: np.ndarray, drop_slip: np.ndarray, labels: _Labels | None,
                 settings: IdentificationSettings, mine: np.ndarray, counts: RowCounts) -> np.ndarray:
    """Rows of a stretch left for the equations (edges, no mode, unselected segments and slip
    dropped), counted in ``counts`` (only the piece's own rows ``mine``; the guards see the others)."""
    if settings.rows.segments is None:
        selected = np.ones(st.n, dtype=bool)
    else:
        wanted = settings.rows.segments
        selected = np.zeros(st.n, dtype=bool) if labels is None else labels.selected(wanted, st.rows)
    in_a_mode = mode != NO_MODE
    counts.edge += int(np.count_nonzero(st.edge & mine))
    rest = ~st.edge
    counts.no_mode += int(np.count_nonzero(rest & ~in_a_mode & mine))
    rest &= in_a_mode
    counts.not_selected += int(np.count_nonzero(rest & ~selected & mine))
    rest &= selected
    counts.slip += int(np.count_nonzero(rest & drop_slip & mine))
    usable = rest & ~drop_slip
    counts.used += int(np.count_nonzero(usable & mine))
    for m, c in enumerate(np.bincount(mode[usable & mine], minlength=len(Mode) + 1).tolist()):
        if c and m != NO_MODE:
            label = Mode(m).label
            counts.per_mode[label] = counts.per_mode.get(label, 0) + c
    if labels is not None:
        _count_mismatch(counts, labels, st.rows, mode)
    return usable


def log_equations(log: Any, geometry: Geometry, settings: IdentificationSettings = IdentificationSettings()
                  ) -> tuple[list[EquationBlock], list[str]]:
    """Equation blocks of every usable row of a log and notes (see :func:`log_rows`)."""
    rows = log_rows(log, geometry, settings)
    return list(rows.blocks), list(rows.notes)
