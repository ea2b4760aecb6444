"""Wheel slip from the redundant rolling constraints (eq. 1-3).

Eight rolling constraints over-determine the three chassis velocities. The slip speed of each
wheel (:func:`agvdyn.odometry.odometry_with_slip`, m/s) is its residual with the chassis velocity
fitted to the other three wheels (the wheel whose removal leaves the others consistent): a single
slipping wheel shows its own slip rather than a share spread over all four. It is taken from the
raw wheel rates and lightly filtered steering rates (``slip_cutoff``), not the regression's 40 rad/s
filter that would smear a 20 ms slip over 0.2 s and shrink it several times. Rows whose slip speed
exceeds a threshold taken from its robust spread are wheel slip: they are dropped, with a guard,
and each event is reported with the first and last row above the threshold (not the guard).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn._jit import njit
from agvdyn.identification.settings import IdentificationSettings
from agvdyn.platform import WHEELS
from agvdyn.signals import row_max_abs, runs

__all__ = ["SlipEvent", "slip_threshold", "slip_rows", "median_and_mad"]

#: Scale of the median absolute deviation to a standard deviation of normal data.
MAD_SCALE = 1.4826


@njit(cache=True, nogil=True)
def median_and_mad(x):  # pragma: no cover - compiled
    """``(median(x), median(|x - median(x)|))`` of a 1-D array, as numpy's, without the GIL (two
    medians of a log's slip speeds held it ~1 ms per log while another thread waited)."""
    m = np.median(x)
    dev = np.empty_like(x)
    for i in range(x.size):
        dev[i] = abs(x[i] - m)
    return m, np.median(dev)


@dataclass(frozen=True)
class SlipEvent:
    """Rows ``t_start..t_end`` of one log whose slip speed exceeded the threshold."""

    source: str
    t_start: float
    t_end: float
    peak_mps: float
    wheels: tuple[str, ...]
    rows: int

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "t_start": self.t_start, "t_end": self.t_end, "peak_mps": self.peak_mps,
                "wheels": list(self.wheels), "rows": self.rows}


def slip_threshold(speed: np.ndarray, settings: IdentificationSettings) -> float:
    """Threshold (m/s) on the largest slip speed of a row: the setting, or robust from the data.

    ``median + slip_spread * 1.4826 * MAD`` of ``speed`` (the rows in a motion mode), at least
    ``slip_floor``: a few short slip events do not move median and MAD, so they stand out.
    """
    if settings.rows.slip_threshold is not None:
        return float(settings.rows.slip_threshold)
    if speed.size == 0:
        return float(settings.rows.slip_floor)
    med, mad = median_and_mad(np.ascontiguousarray(speed, dtype=float))
    mad = MAD_SCALE * float(mad)
    return max(float(med) + settings.rows.slip_spread * mad, float(settings.rows.slip_floor))


def slip_rows(source: str, t: np.ndarray, slip: np.ndarray, threshold: float, guard_rows: int,
              peaks: np.ndarray | None = None) -> tuple[np.ndarray, list[SlipEvent]]:
    """Rows to drop (slip rows and ``guard_rows`` either side) and the slip events of one stretch.

    Slip rows closer than ``2 * guard_rows`` are one event. ``peaks``: ``row_max_abs(slip)`` when
    already known.
    """
    n = t.size
    hit = (row_max_abs(slip) if peaks is None else peaks) > threshold
    if not hit.any():
        return np.zeros(n, dtype=bool), []
    over = slip > threshold
    cs = np.concatenate([[0], np.cumsum(hit)])
    lo = np.clip(np.arange(n) - guard_rows, 0, n)
    hi = np.clip(np.arange(n) + guard_rows + 1, 0, n)
    drop = cs[hi] - cs[lo] > 0
    events = []
    for a, b in runs(drop):
        if not drop[a]:
            continue
        inside = np.flatnonzero(hit[a:b]) + a
        first, last = int(inside[0]), int(inside[-1])
        wheels = tuple(w for i, w in enumerate(WHEELS) if over[first:last + 1, i].any())
        events.append(SlipEvent(source, float(t[first]), float(t[last]), float(slip[first:last + 1].max()),
                                wheels, int(hit[first:last + 1].sum())))
    return drop, events
