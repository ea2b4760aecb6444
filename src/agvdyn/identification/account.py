"""What the row pass (:func:`agvdyn.identification.rows.log_rows`) gives: the rows of one log
(:class:`LogRows`), the account of its samples (:class:`RowCounts`), and the account of all logs
of one identification (:class:`RowAccount`), which the fit puts in the result."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agvdyn.identification.equations import EquationBlock
from agvdyn.identification.slip import SlipEvent

__all__ = ["RowCounts", "LogRows", "RowAccount"]


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
    #: Stribeck model: used rows of each joint group (l, r, w) within its Stribeck range (.model_rows).
    stribeck_support: dict[str, int] = field(default_factory=dict)

    def add(self, other: "RowCounts") -> None:
        for key in ("samples", "stretches", "edge", "too_short", "no_mode", "not_selected", "slip", "used"):
            setattr(self, key, getattr(self, key) + getattr(other, key))
        for key in ("per_mode", "label_mismatch", "clipped_stop", "stribeck_support"):
            mine = getattr(self, key)
            for k, v in getattr(other, key).items():
                mine[k] = mine.get(k, 0) + v

    def to_dict(self) -> dict[str, Any]:
        return {"samples": self.samples, "stretches": self.stretches, "dropped_edge": self.edge,
                "dropped_too_short": self.too_short, "dropped_no_mode": self.no_mode,
                "dropped_not_selected": self.not_selected, "dropped_slip": self.slip, "used": self.used,
                "per_mode": dict(self.per_mode), "label_mismatch": dict(self.label_mismatch),
                "clipped_stop": dict(self.clipped_stop),
                **({"stribeck_support": dict(self.stribeck_support)} if self.stribeck_support else {})}


@dataclass(frozen=True, eq=False)
class LogRows:
    """The row pass of one log (or piece of a long log, :func:`log_rows`): what the fit, the
    pre-flight check and the report read.

    ``blocks``: the kept rows as equation blocks (eq. 19); ``counts``: the account of the samples;
    ``slip_events`` and the ``slip_threshold`` (m/s) they were found with; ``notes`` (stretch cuts,
    stretches skipped); ``modes`` (N,) the mode of every sample (0: none, or not filtered);
    ``cuts``: why the log was cut into stretches (:func:`.stretches.stretch_bounds`), ``gaps``:
    the time intervals between its stretches (t of the last row before, of the first row after);
    ``labels``: the segment labels the log carries.
    """

    source: str
    blocks: tuple[EquationBlock, ...]
    counts: RowCounts
    slip_events: tuple[SlipEvent, ...]
    slip_threshold: float
    notes: tuple[str, ...]
    modes: np.ndarray
    cuts: tuple[str, ...] = ()
    gaps: tuple[tuple[float, float], ...] = ()
    labels: frozenset[str] = frozenset()


@dataclass
class RowAccount:
    """The rows of all logs of one identification, added in log order (:meth:`add`): the account
    the result carries (counts, slip events and thresholds, notes, sources, samples), the labels
    present, and the blocks when they are kept."""

    counts: RowCounts = field(default_factory=RowCounts)
    blocks: list[EquationBlock] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    slip_events: list[SlipEvent] = field(default_factory=list)
    slip_thresholds: dict[str, float] = field(default_factory=dict)
    sources: list[str] = field(default_factory=list)
    labels: set[str] = field(default_factory=set)
    n_samples: int = 0

    def add(self, rows: LogRows, source: str, *, piece: bool = False, keep_blocks: bool = True) -> None:
        """Add one log's row pass; ``piece``: a piece of a long log (the pieces of one file are one source)."""
        if keep_blocks:
            self.blocks += rows.blocks
        self.notes += rows.notes
        self.counts.add(rows.counts)
        self.slip_events += rows.slip_events
        self.slip_thresholds[rows.source] = rows.slip_threshold
        if not piece or not self.sources or self.sources[-1] != source:
            self.sources.append(source)
        self.labels |= rows.labels
        self.n_samples += rows.counts.samples
