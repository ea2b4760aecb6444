"""Mapping files: which joint (ROS 2 bag) or column (CSV/Parquet table) is which log quantity.

A mapping file is YAML; see ``docs/io.md`` and ``examples/mappings/`` for the documented
format. It is read strictly: unknown keys, wrong types and missing required entries are
errors naming the file and the key. Conversion of one signal to SI units is affine::

    value_SI = sign * scale * unit_factor * raw / (i_G if the side needs it) + offset

with ``unit_factor`` 1 (rad), pi/180 (deg), 2 pi (rev), 2 pi / counts_per_rev (counts) for
angles, and 1 (Nm), 1e-3 (mNm), torque_constant (A) for torques. Wheel angles measured on
the motor side and torques measured on the wheel side are divided by the gear ratio ``i_G``
(PLATFORM.md: beta is wheel side, M_mot motor side). The gear ratio comes from the platform
given to the reader or from the mapping's optional top-level ``i_G``; a mapping with such signals
and neither is refused (:func:`gear_ratio`), never converted with an assumed ratio.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from agvdyn.io.log import ALPHA_COLUMNS, BETA_COLUMNS, TORQUE_COLUMNS


class MappingError(ValueError):
    """A mapping file that cannot be used; the message names the file and the key."""


class InputKind(str, Enum):
    """What a mapping reads: a ROS 2 bag with JointState messages, or a table (CSV/Parquet)."""

    ROS2_BAG = "ros2_bag"
    TABLE = "table"


class Stamps(str, Enum):
    """Time of a bag message: its header stamp (receive time if all stamps are zero) or the receive time."""

    HEADER = "header"
    RECEIVE = "receive"


class Side(str, Enum):
    """Which side of the gear a wheel angle or a torque is measured on."""

    WHEEL = "wheel"
    MOTOR = "motor"


class TimeUnit(str, Enum):
    S = "s"
    MS = "ms"
    US = "us"
    NS = "ns"

    @property
    def factor(self) -> float:
        """Seconds per unit."""
        return {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[self.value]


#: Units of angles and their factor to rad (``counts`` needs counts_per_rev).
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0, "rev": 2.0 * math.pi, "counts": None}
#: Units of torques and their factor to N m (``A`` needs torque_constant in N m / A).
TORQUE_UNITS = {"Nm": 1.0, "mNm": 1e-3, "A": None}
#: Rear wheel headings that may be mapped to check the mirror coupling (PLATFORM.md):
#: heading_rl = -alpha_l, heading_rr = -alpha_r.
HEADING_QUANTITIES = {"heading_rl": "alpha_l", "heading_rr": "alpha_r"}
#: Quantities a mapping must provide, then those it may provide.
REQUIRED_QUANTITIES = ALPHA_COLUMNS + BETA_COLUMNS + TORQUE_COLUMNS
OPTIONAL_QUANTITIES = tuple(HEADING_QUANTITIES)
DEFAULT_TOPIC = "/joint_states"
#: Default tolerance of the mirror coupling check, rad (about 1.1 degrees).
DEFAULT_COUPLING_TOLERANCE = 0.02


def quantity_kind(quantity: str) -> str:
    """``"angle"`` for alpha/beta/heading quantities, ``"torque"`` for motor torques."""
    return "torque" if quantity in TORQUE_COLUMNS else "angle"


@dataclass(frozen=True)
class Signal:
    """How one log quantity is obtained from one joint or column.

    Attributes
    ----------
    quantity : log quantity (``alpha_l``, ``beta_fl``, ``m_fl``, ... or ``heading_rl``/``heading_rr``).
    source : joint name (bags; position for angles, effort for torques) or column name (tables).
    unit : one of :data:`ANGLE_UNITS` or :data:`TORQUE_UNITS`.
    sign : +1 or -1.
    scale : extra factor on the raw value (for example 0.1 for a value logged in tenths).
    offset : added after conversion, SI units (an encoder zero, a torque sensor bias).
    side : gear side of a wheel angle (default wheel) or torque (default motor); None for steering.
    counts_per_rev : encoder counts per revolution when ``unit`` is ``counts``.
    torque_constant : N m per A when ``unit`` is ``A`` (torque on ``side``).
    """

    quantity: str
    source: str
    unit: str
    sign: float = 1.0
    scale: float = 1.0
    offset: float = 0.0
    side: Side | None = None
    counts_per_rev: float | None = None
    torque_constant: float | None = None

    @property
    def kind(self) -> str:
        return quantity_kind(self.quantity)

    @property
    def field(self) -> str:
        """JointState field read for this quantity."""
        return "effort" if self.kind == "torque" else "position"

    @property
    def needs_gear_ratio(self) -> bool:
        """True for a wheel angle measured on the motor side or a torque measured on the wheel side."""
        return (self.kind == "angle" and self.side is Side.MOTOR) or (self.kind == "torque" and self.side is Side.WHEEL)

    def unit_factor(self) -> float:
        if self.unit == "counts":
            return 2.0 * math.pi / float(self.counts_per_rev)
        if self.unit == "A":
            return float(self.torque_constant)
        return float((ANGLE_UNITS | TORQUE_UNITS)[self.unit])

    def gain(self, i_G: float | None) -> float:
        """Factor from the raw value to SI units on the side PLATFORM.md uses.

        ``i_G`` may be None for signals that do not need it (:attr:`needs_gear_ratio`).
        """
        gear = 1.0
        if self.needs_gear_ratio:
            if i_G is None:
                raise MappingError(f"signals.{self.quantity}: side {self.side.value} needs the gear ratio i_G, none given")
            gear = 1.0 / i_G  # motor encoder / i_G = wheel angle; wheel torque / i_G = motor torque
        return self.sign * self.scale * self.unit_factor() * gear

    def to_si(self, raw: np.ndarray, i_G: float | None) -> np.ndarray:
        """Raw values -> SI values of the log quantity."""
        return np.asarray(raw, dtype=np.float64) * self.gain(i_G) + self.offset

    def from_si(self, value: np.ndarray, i_G: float | None) -> np.ndarray:
        """SI values of the log quantity -> raw values (inverse of :meth:`to_si`)."""
        return (np.asarray(value, dtype=np.float64) - self.offset) / self.gain(i_G)


@dataclass(frozen=True)
class SegmentRange:
    """Rows with ``start <= t < end`` (log time, s) belong to segment ``name``."""

    name: str
    start: float
    end: float


@dataclass(frozen=True)
class SegmentColumn:
    """Segment names taken from a table column, translated by ``names`` (raw value -> segment name)."""

    column: str
    names: tuple[tuple[str, str], ...] = ()

    def translate(self, raw: str) -> str:
        return dict(self.names).get(raw, raw)


@dataclass(frozen=True)
class LogMapping:
    """A checked mapping file (see module docstring and ``docs/io.md``).

    ``rate`` (Hz) is the rate of the uniform time base bags are resampled onto (None: the
    joints' interval from their stamps, :func:`agvdyn.time_base.stamp_interval`, rounded to 1 ns);
    tables are resampled only when it is given.
    ``max_gap`` (s) is the longest interval between two samples of one signal that is
    interpolated over (None: 5 nominal intervals of the source or of the time base, whichever
    is longer). ``time_column``/``time_unit`` apply to tables. ``i_G`` (optional) is the gear
    ratio for motor-side wheel angles and wheel-side torques when no platform is given.
    """

    input: InputKind
    signals: tuple[Signal, ...]
    topic: str = DEFAULT_TOPIC
    stamps: Stamps = Stamps.HEADER
    rate: float | None = None
    max_gap: float | None = None
    time_column: str = "t"
    time_unit: TimeUnit = TimeUnit.S
    coupling_tolerance: float = DEFAULT_COUPLING_TOLERANCE
    segments: tuple[SegmentRange, ...] | SegmentColumn | None = None
    path: Path | None = None
    i_G: float | None = None

    def __post_init__(self) -> None:
        names = [s.quantity for s in self.signals]
        missing = [q for q in REQUIRED_QUANTITIES if q not in names]
        if missing:
            raise MappingError(f"{self._where()}signals: missing {missing}: a mapping must give all of {list(REQUIRED_QUANTITIES)}")
        if len(set(names)) != len(names):
            raise MappingError(f"{self._where()}signals: a quantity is mapped twice")
        if self.i_G is not None and not (isinstance(self.i_G, (int, float)) and math.isfinite(self.i_G) and self.i_G > 0):
            raise MappingError(f"{self._where()}i_G: {self.i_G}: expected a number > 0")

    @property
    def gear_quantities(self) -> tuple[str, ...]:
        """Quantities whose conversion needs the gear ratio (motor-side wheel angles, wheel-side torques)."""
        return tuple(s.quantity for s in self.signals if s.needs_gear_ratio)

    def _where(self) -> str:
        return f"{self.path}: " if self.path is not None else ""

    def signal(self, quantity: str) -> Signal | None:
        """The signal of ``quantity``, None if the mapping does not map it (optional quantities)."""
        return next((s for s in self.signals if s.quantity == quantity), None)

    @property
    def sources(self) -> tuple[str, ...]:
        """Joint or column names used, in order of first use."""
        return tuple(dict.fromkeys(s.source for s in self.signals))

    def to_dict(self) -> dict[str, Any]:
        """Plain form for sidecars and for writing the mapping back."""
        out: dict[str, Any] = {"input": self.input.value}
        if self.input is InputKind.ROS2_BAG:
            out.update(topic=self.topic, stamps=self.stamps.value)
        else:
            out["time"] = {"column": self.time_column, "unit": self.time_unit.value}
        if self.rate is not None:
            out["rate"] = self.rate
        if self.max_gap is not None:
            out["max_gap"] = self.max_gap
        if self.i_G is not None:
            out["i_G"] = self.i_G
        out["coupling_tolerance"] = self.coupling_tolerance
        key = "joint" if self.input is InputKind.ROS2_BAG else "column"
        sig: dict[str, Any] = {}
        for s in self.signals:
            entry: dict[str, Any] = {key: s.source, "unit": s.unit}
            for name in ("sign", "scale", "offset"):
                if getattr(s, name) != (1.0 if name != "offset" else 0.0):
                    entry[name] = getattr(s, name)
            if s.side is not None:
                entry["side"] = s.side.value
            if s.counts_per_rev is not None:
                entry["counts_per_rev"] = s.counts_per_rev
            if s.torque_constant is not None:
                entry["torque_constant"] = s.torque_constant
            sig[s.quantity] = entry
        out["signals"] = sig
        if isinstance(self.segments, SegmentColumn):
            out["segments"] = {"column": self.segments.column, "names": dict(self.segments.names)}
        elif self.segments:
            out["segments"] = [{"name": r.name, "start": r.start, "end": r.end} for r in self.segments]
        return out


# --- parsing ---------------------------------------------------------------------------------


def gear_ratio(mapping: LogMapping, platform: Any = None) -> tuple[float | None, str | None]:
    """The gear ratio ``i_G`` a conversion with ``mapping`` uses, and where it comes from.

    Parameters
    ----------
    mapping : the mapping; its optional ``i_G`` is used when no platform is given.
    platform : a :class:`agvdyn.platform.Geometry` (anything with ``i_G`` and ``name``) or None.

    Returns
    -------
    (i_G, source) : the ratio and ``"platform <name>"`` or ``"mapping"``; ``(None, None)`` when no
        signal needs it and none is given.

    Raises
    ------
    MappingError
        Signals need the gear ratio (:attr:`LogMapping.gear_quantities`) and neither a platform
        nor the mapping's ``i_G`` gives it; or both give it and disagree.
    """
    where = f"{mapping.path}: " if mapping.path is not None else "mapping: "
    if platform is not None and mapping.i_G is not None and not math.isclose(float(platform.i_G), mapping.i_G, rel_tol=1e-12):
        raise MappingError(
            f"{where}i_G: the mapping declares i_G: {mapping.i_G:.6g} but the platform {getattr(platform, 'name', '')!s} "
            f"has i_G = {float(platform.i_G):.6g}: the gear ratio must be given once or agree "
            "(remove i_G from the mapping, or use the platform file of this vehicle)"
        )
    if platform is not None:
        return float(platform.i_G), f"platform {getattr(platform, 'name', '')!s}".rstrip()
    if mapping.i_G is not None:
        return mapping.i_G, "mapping"
    needs = mapping.gear_quantities
    if needs:
        described = ", ".join(f"{q} ({mapping.signal(q).source!r}, side: {mapping.signal(q).side.value})" for q in needs)
        raise MappingError(
            f"{where}the signals {described} need the gear ratio i_G (motor-side wheel angles and wheel-side "
            "torques are divided by it), but neither a platform nor the mapping gives it: pass the platform "
            "(--platform FILE on the command line, platform= in Python) or declare it in the mapping with a "
            "top-level line 'i_G: <ratio>' (wheel torque / motor torque, for example i_G: 25)"
        )
    return None, None
