"""The segment names of a log and the motion mode each names, written once (PLATFORM.md "Files",
column ``segment``).

A segment name is the operator's word for an experiment, not a measurement: the identification
decides every row's mode from its configuration and uses a label only as a hint. Everything that
needs the names derives from :data:`VOCABULARY`: the log schema (:data:`agvdyn.io.SEGMENTS`, the
order of the codes of the ``segment`` column), the trajectories' segment names
(:data:`agvdyn.trajectories.SEGMENT_NAMES`), the planner's phases, the label-driven row selection
(:data:`agvdyn.signals.SEGMENT_MODES`), the label check of the identification
(:data:`agvdyn.identification.rows.LABEL_MODES`) and the colours of the report's label lane.

Modes are written as the labels of :class:`agvdyn.kinematics.Mode` (``"1"``, ``"2"``, ``"2s"``,
``"3"``, ``"4"``), so that this module imports nothing (the log schema reads it without the
kinematics); ``Mode.from_label`` turns them into modes.

>>> segment_mode("straight")
'2s'
>>> IDENTIFICATION_SEGMENTS
('steer_left', 'steer_right', 'straight', 'rotation')
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SegmentName", "VOCABULARY", "SEGMENTS", "IDENTIFICATION_SEGMENTS", "MODE_LABELS", "segment_mode",
           "label_modes"]

#: Labels of the motion modes (``Mode.label``), in the order of eq. (9).
MODE_LABELS = ("1", "2", "2s", "3", "4")


@dataclass(frozen=True)
class SegmentName:
    """One segment name: ``mode``, the label of the motion mode its experiment drives (None: no
    mode of the chassis, the wheels turn on jacks); ``also``, labels of further modes its rows may
    be in (the straight stretches of a lane change); ``regression``, False when a label-driven row
    selection leaves its rows out (``align``: a short rate-limited transition between experiments,
    next to the accelerating and braking rows where the wheels slip most)."""

    name: str
    mode: str | None
    also: tuple[str, ...] = ()
    regression: bool = True

    def __post_init__(self) -> None:
        for label in (*((self.mode,) if self.mode is not None else ()), *self.also):
            if label not in MODE_LABELS:
                raise ValueError(f"segment {self.name!r}: mode label {label!r}: expected one of {list(MODE_LABELS)}")

    @property
    def modes(self) -> tuple[str, ...]:
        """Labels of every mode the segment's rows may be in (empty: none)."""
        return () if self.mode is None else (self.mode, *self.also)


#: The known segment names, in the order of the codes of a log's ``segment`` column (never reorder:
#: files store the codes): the identification sequence of sec. 6.2, the validation manoeuvres of
#: sec. 7, ``align`` (wheel alignment at rest between segments, mode 1) and the lifted-wheel test.
VOCABULARY: tuple[SegmentName, ...] = (
    SegmentName("steer_left", "1"),
    SegmentName("steer_right", "1"),
    SegmentName("straight", "2s"),
    SegmentName("rotation", "4"),
    SegmentName("lateral", "3"),
    SegmentName("lane_change", "2", also=("2s",)),
    SegmentName("align", "1", regression=False),
    SegmentName("lifted_wheel", None, regression=False),
)
#: The names alone, in file order.
SEGMENTS: tuple[str, ...] = tuple(s.name for s in VOCABULARY)
#: The paper's identification experiments in their execution order (sec. 6.2): the planner's phases.
IDENTIFICATION_SEGMENTS: tuple[str, ...] = ("steer_left", "steer_right", "straight", "rotation")

_BY_NAME = {s.name: s for s in VOCABULARY}


def segment_mode(name: str) -> str | None:
    """Label of the mode a segment name names (None: none); ``KeyError`` naming the known names."""
    try:
        return _BY_NAME[name].mode
    except KeyError:
        raise KeyError(f"unknown segment name {name!r}: expected one of {list(SEGMENTS)}") from None


def label_modes() -> dict[str, tuple[str, ...]]:
    """``{name: labels of the modes its rows may be in}`` of the names that name a mode."""
    return {s.name: s.modes for s in VOCABULARY if s.modes}
