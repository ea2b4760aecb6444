"""Wheel-slip scenarios of the simulated vehicle: low-friction floor patches and motor torque bursts.

Off by default (``SlipSettings()`` has neither). Two ways to make the wheels slip, combinable:

- :class:`FrictionPatch`: a rectangle of floor in the world frame of the start of the run
  (``x``, ``y``: ``(min, max)`` in m, None = unbounded) and/or a time window (``t``: ``(start,
  end)`` in s, None = always) in which the tyre friction coefficient ``mu`` of every wheel whose
  contact point is inside is multiplied by ``mu_factor``. The contact point is the true one
  (chassis pose, steering angle and the offset ``a`` along the axle, PLATFORM.md), checked at
  every plant substep. Where patches overlap, the smallest factor applies.
- :class:`TorqueBurst`: from time ``t`` for ``duration`` seconds an extra motor torque ``torque``
  (N m, motor side) on the listed ``wheels``, added after the drive's torque limit and not known
  to the controller (a disturbance of the drive, such as a current-controller glitch). The
  motors apply it, so the measured torques of the log contain it: the log stays consistent
  with the dynamics except for the slip itself. Overlapping bursts add up.

A patch alone rarely makes a wheel slip on the built-in experiments (their tyre forces stay
near 100 N, the friction limit ``mu F_z`` is 1650 N, 250 N at ``mu_factor`` 0.15); a burst
alone needs more than the torque limit plus ``mu F_z r / i_G`` (~13 N m at full friction, as
the controller pushes back with up to its 6 N m). :data:`SLIP_SCENARIO` combines them.

The true slip of a run is ``SimulationResult.slip_speed`` (N, 4): the norm of the lateral and
longitudinal slip velocity ``A(alpha) v`` of each contact point (true rolling radii), and
``SimulationResult.slip_intervals(threshold)`` the intervals in which it exceeds a threshold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from agvdyn.platform import WHEELS

#: Slip speed (m/s) above which a contact point counts as slipping (sidecar ``slip_truth``).
#: The tyres of the plant always creep a little: below 0.006 m/s in the built-in experiments.
SLIP_THRESHOLD = 0.05

_UNBOUNDED = math.inf


def _interval(where: str, key: str, value: Any, allow_negative: bool = True) -> tuple[float, float] | None:
    if value is None:
        return None
    ok = (isinstance(value, (list, tuple)) and len(value) == 2
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
          and value[0] < value[1] and (allow_negative or value[0] >= 0))
    if not ok:
        raise ValueError(f"{where}{key}={value!r}: expected [min, max] with finite min < max"
                         f"{'' if allow_negative else ', min >= 0'}, or null for unbounded")
    return (float(value[0]), float(value[1]))


def _number(where: str, key: str, value: Any, low: float = -math.inf, high: float = math.inf,
            low_open: bool = False, expected: str = "a finite number") -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value > low if low_open else value >= low) and value <= high
    if not ok:
        raise ValueError(f"{where}{key}={value!r}: expected {expected}")
    return float(value)


@dataclass(frozen=True)
class FrictionPatch:
    """Floor where ``mu`` is multiplied by ``mu_factor`` in (0, 1]: rectangle ``x`` x ``y`` (world
    frame of the start, m) during ``t`` (s); a None bound is unbounded (None everywhere: the whole
    floor, always)."""

    mu_factor: float = 0.15
    x: tuple[float, float] | None = None
    y: tuple[float, float] | None = None
    t: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        where = "patch: "
        object.__setattr__(self, "mu_factor", _number(where, "mu_factor", self.mu_factor, 0.0, 1.0, low_open=True,
                                                      expected="a number in (0, 1] (the factor on mu)"))
        for key in ("x", "y"):
            object.__setattr__(self, key, _interval(where, key, getattr(self, key)))
        object.__setattr__(self, "t", _interval(where, "t", self.t, allow_negative=False))

    def row(self) -> list[float]:
        """(x_min, x_max, y_min, y_max, t_start, t_end, mu_factor) for the compiled plant (inf = unbounded)."""
        x = self.x or (-_UNBOUNDED, _UNBOUNDED)
        y = self.y or (-_UNBOUNDED, _UNBOUNDED)
        t = self.t or (-_UNBOUNDED, _UNBOUNDED)
        return [*x, *y, *t, self.mu_factor]

    def to_dict(self) -> dict[str, Any]:
        return {"mu_factor": self.mu_factor, **{k: None if getattr(self, k) is None else list(getattr(self, k))
                                                for k in ("x", "y", "t")}}


@dataclass(frozen=True)
class TorqueBurst:
    """Extra motor torque ``torque`` (N m, motor side) on ``wheels`` from ``t`` (s) for ``duration`` (s)."""

    t: float
    torque: float
    duration: float = 0.08
    wheels: tuple[str, ...] = WHEELS

    def __post_init__(self) -> None:
        where = "burst: "
        object.__setattr__(self, "t", _number(where, "t", self.t, 0.0, expected="a start time >= 0 s"))
        object.__setattr__(self, "torque", _number(where, "torque", self.torque, expected="a finite torque in N m"))
        object.__setattr__(self, "duration", _number(where, "duration", self.duration, 0.0, low_open=True,
                                                     expected="a duration > 0 s"))
        wheels = self.wheels
        if isinstance(wheels, str):
            wheels = (wheels,)
        if (not isinstance(wheels, (list, tuple)) or not wheels or any(w not in WHEELS for w in wheels)
                or len(set(wheels)) != len(wheels)):
            raise ValueError(f"{where}wheels={self.wheels!r}: expected distinct wheel names from {list(WHEELS)}")
        object.__setattr__(self, "wheels", tuple(wheels))

    def to_dict(self) -> dict[str, Any]:
        return {"t": self.t, "torque": self.torque, "duration": self.duration, "wheels": list(self.wheels)}


@dataclass(frozen=True)
class SlipSettings:
    """Slip scenario: friction ``patches`` and torque ``bursts`` (both empty by default: no scenario)."""

    patches: tuple[FrictionPatch, ...] = ()
    bursts: tuple[TorqueBurst, ...] = ()

    def __post_init__(self) -> None:
        for key, cls in (("patches", FrictionPatch), ("bursts", TorqueBurst)):
            items = getattr(self, key)
            if not isinstance(items, (list, tuple)) or not all(isinstance(p, cls) for p in items):
                raise ValueError(f"slip setting {key}={items!r}: expected a list of {cls.__name__}")
            object.__setattr__(self, key, tuple(items))

    @property
    def active(self) -> bool:
        return bool(self.patches or self.bursts)

    def patch_table(self) -> np.ndarray:
        """Patches as a (P, 7) array for the compiled plant (see :meth:`FrictionPatch.row`)."""
        return np.array([p.row() for p in self.patches], dtype=float).reshape(len(self.patches), 7)

    def burst_torques(self, t: np.ndarray) -> np.ndarray:
        """Burst torques (N, 4), N m motor side, held over each sample of the times ``t`` (N,)."""
        t = np.asarray(t, dtype=float)
        out = np.zeros((t.size, 4))
        tol = 1e-9
        for b in self.bursts:
            on = (t >= b.t - tol) & (t < b.t + b.duration - tol)
            for w in b.wheels:
                out[on, WHEELS.index(w)] += b.torque
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"patches": [p.to_dict() for p in self.patches], "bursts": [b.to_dict() for b in self.bursts]}

    @classmethod
    def from_dict(cls, data: Any, source: str = "<settings>") -> "SlipSettings":
        """From ``{patches: [{mu_factor, x, y, t}, ...], bursts: [{t, torque, duration, wheels}, ...]}``;
        errors name the source, the entry, the key and the value."""
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise ValueError(f"{source}: slip: expected a mapping with patches and/or bursts, found {data!r}")
        bad = set(data) - {"patches", "bursts"}
        if bad:
            raise ValueError(f"{source}: slip: unknown keys {sorted(bad)}: expected some of ['bursts', 'patches']")
        built: dict[str, list] = {}
        for key, item_cls in (("patches", FrictionPatch), ("bursts", TorqueBurst)):
            items = data.get(key) or []
            if not isinstance(items, list):
                raise ValueError(f"{source}: slip: {key}={items!r}: expected a list of mappings")
            allowed = set(item_cls.__dataclass_fields__)
            built[key] = []
            for n, item in enumerate(items):
                where = f"{source}: slip: {key}[{n}]"
                if not isinstance(item, dict):
                    raise ValueError(f"{where}: {item!r}: expected a mapping with keys {sorted(allowed)}")
                unknown = set(item) - allowed
                if unknown:
                    raise ValueError(f"{where}: unknown keys {sorted(unknown)}: expected some of {sorted(allowed)}")
                try:
                    built[key].append(item_cls(**item))
                except TypeError as exc:
                    raise ValueError(f"{where}: {exc}") from exc
                except ValueError as exc:
                    raise ValueError(f"{where}: {str(exc).split(': ', 1)[1]}") from exc
        return cls(tuple(built["patches"]), tuple(built["bursts"]))


#: The slip scenario of ``agvdyn simulate --slip``, tuned for the built-in ``identification``
#: experiment on the prototype (world frame of the start: the ``straight`` runs along +x up to
#: X = 2 m, the ``rotation`` turns about the origin). A slippery strip of floor at 1.75 <= x < 2.35 m
#: that only the front wheels reach (X from 1.15 to 1.75 m), a whole floor slippery from 105.4 to
#: 105.7 s, and five bursts: straight, all wheels, +3 N m at 67.0 s (front wheels on the strip:
#: they slip), +3 N m at 73.0 s (front wheels past the strip: no slip), -3 N m at 75.5 s (on the
#: strip again: slip); rotation, +12 N m on all wheels at 96.0 s (normal floor: mode 4 admits no
#: translation, all four slip) and +3 N m on rl and fr at 105.5 s (slippery window). Seed 1:
#: four slip events, 140 samples above 0.05 m/s (docs/simulation.md).
SLIP_SCENARIO = SlipSettings(
    patches=(
        FrictionPatch(mu_factor=0.15, x=(1.75, 2.35), y=(-1.5, 1.5)),
        FrictionPatch(mu_factor=0.15, t=(105.4, 105.7)),
    ),
    bursts=(
        TorqueBurst(t=67.0, torque=3.0, duration=0.08),
        TorqueBurst(t=73.0, torque=3.0, duration=0.08),
        TorqueBurst(t=75.5, torque=-3.0, duration=0.08),
        TorqueBurst(t=96.0, torque=12.0, duration=0.06),
        TorqueBurst(t=105.5, torque=3.0, duration=0.06, wheels=("rl", "fr")),
    ),
)


class SlipInterval(NamedTuple):
    """An interval of true wheel slip: first and last sample time above the threshold (s), the
    peak slip speed (m/s) and the wheels that slipped (PLATFORM.md order)."""

    t_start: float
    t_end: float
    peak: float
    wheels: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"t_start": self.t_start, "t_end": self.t_end, "peak_mps": self.peak, "wheels": list(self.wheels)}


#: Slip intervals closer than this (s) are one event: a burst makes the wheels slip as it starts
#: and, with the controller's counter-torque, again as it ends.
MERGE_GAP = 0.1


def slip_intervals(t: np.ndarray, slip_speed: np.ndarray, threshold: float = SLIP_THRESHOLD,
                   merge_gap: float = MERGE_GAP) -> list[SlipInterval]:
    """Intervals in which any wheel's slip speed (N, 4) exceeds ``threshold`` (m/s): runs of
    consecutive samples, runs at most ``merge_gap`` seconds apart merged into one (0: no merging).
    ``t_start`` / ``t_end`` are the first / last sample above the threshold, ``peak`` the largest
    slip speed and ``wheels`` the wheels above the threshold within the interval."""
    threshold = _number("", "threshold", threshold, 0.0, low_open=True, expected="a slip speed > 0 m/s")
    merge_gap = _number("", "merge_gap", merge_gap, 0.0, expected="a gap >= 0 s")
    t = np.asarray(t, dtype=float)
    slip_speed = np.asarray(slip_speed, dtype=float)
    over = slip_speed > threshold
    rows = np.flatnonzero(over.any(axis=1))
    if rows.size == 0:
        return []
    breaks = np.flatnonzero((np.diff(rows) > 1) & (t[rows[1:]] - t[rows[:-1]] > merge_gap + 1e-9))
    starts = np.r_[rows[0], rows[breaks + 1]]
    ends = np.r_[rows[breaks], rows[-1]]
    out = []
    for a, b in zip(starts, ends):
        sl = slice(a, b + 1)
        wheels = tuple(w for i, w in enumerate(WHEELS) if over[sl, i].any())
        out.append(SlipInterval(float(t[a]), float(t[b]), float(slip_speed[sl].max()), wheels))
    return out


__all__ = ["SLIP_THRESHOLD", "MERGE_GAP", "SLIP_SCENARIO", "FrictionPatch", "TorqueBurst", "SlipSettings",
           "SlipInterval", "slip_intervals"]
