"""Mapping files (YAML): strict reading into a :class:`agvdyn.io.mapping.LogMapping`, with errors
that name the file, the key and the value."""
from __future__ import annotations

import math
import os
from enum import Enum
from pathlib import Path
from typing import Any
import yaml
from agvdyn.io.sidecar import _LOADER
from agvdyn.io.log import BETA_COLUMNS, SEGMENTS, TORQUE_COLUMNS
from agvdyn.io.mapping import (
    ANGLE_UNITS,
    DEFAULT_COUPLING_TOLERANCE,
    DEFAULT_TOPIC,
    OPTIONAL_QUANTITIES,
    REQUIRED_QUANTITIES,
    TORQUE_UNITS,
    InputKind,
    LogMapping,
    MappingError,
    SegmentColumn,
    SegmentRange,
    Side,
    Signal,
    Stamps,
    TimeUnit,
    quantity_kind,
)

__all__ = ["mapping_from_dict", "read_mapping"]


_TOP_KEYS = {"input", "topic", "stamps", "rate", "max_gap", "time", "coupling_tolerance", "signals", "segments", "description", "i_G"}
_SIGNAL_KEYS = {"joint", "column", "unit", "sign", "scale", "offset", "side", "counts_per_rev", "torque_constant"}


class _Reader:
    """Strict access to a parsed YAML mapping, with error messages naming file and key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, message: str) -> MappingError:
        return MappingError(f"{self.source}: {key}: {message}")

    def unknown(self, data: dict, allowed: set[str], where: str) -> None:
        extra = [k for k in data if k not in allowed]
        if extra:
            raise self.fail(f"{where}{extra[0]}", f"unknown key: expected one of {sorted(allowed)}")

    def number(self, key: str, value: Any, *, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(key, f"{value!r} is not a finite number")
        if positive and value <= 0:
            raise self.fail(key, f"{value!r}: expected a number > 0")
        return float(value)

    def text(self, key: str, value: Any) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(key, f"{value!r}: expected a non-empty string")
        return value

    def choice(self, key: str, value: Any, enum: type[Enum]) -> Any:
        try:
            return enum(value)
        except ValueError:
            raise self.fail(key, f"{value!r}: expected one of {[e.value for e in enum]}") from None

    def mapping(self, key: str, value: Any) -> dict:
        if not isinstance(value, dict):
            raise self.fail(key, f"expected a mapping, found {type(value).__name__}")
        return value


def _signal(r: _Reader, quantity: str, entry: Any, kind: InputKind) -> Signal:
    where = f"signals.{quantity}"
    if isinstance(entry, str):  # shorthand: just the joint or column name
        entry = {"joint" if kind is InputKind.ROS2_BAG else "column": entry}
    entry = r.mapping(where, entry)
    r.unknown(entry, _SIGNAL_KEYS, f"{where}.")
    src_key, other = ("joint", "column") if kind is InputKind.ROS2_BAG else ("column", "joint")
    if other in entry:
        raise r.fail(f"{where}.{other}", f"not allowed for input {kind.value}: use '{src_key}'")
    if src_key not in entry:
        raise r.fail(where, f"missing '{src_key}'")
    source = r.text(f"{where}.{src_key}", entry[src_key])
    qkind = quantity_kind(quantity)
    units = ANGLE_UNITS if qkind == "angle" else TORQUE_UNITS
    unit = entry.get("unit", "rad" if qkind == "angle" else "Nm")
    if unit not in units:
        raise r.fail(f"{where}.unit", f"{unit!r}: expected one of {list(units)} for {'an angle' if qkind == 'angle' else 'a torque'}")
    sign = r.number(f"{where}.sign", entry.get("sign", 1))
    if sign not in (1.0, -1.0):
        raise r.fail(f"{where}.sign", f"{entry['sign']!r}: expected 1 or -1")
    scale = r.number(f"{where}.scale", entry.get("scale", 1.0))
    if scale == 0:
        raise r.fail(f"{where}.scale", "expected a non-zero number")
    offset = r.number(f"{where}.offset", entry.get("offset", 0.0))
    side: Side | None = None
    if quantity in BETA_COLUMNS:
        side = r.choice(f"{where}.side", entry.get("side", "wheel"), Side)
    elif quantity in TORQUE_COLUMNS:
        side = r.choice(f"{where}.side", entry.get("side", "motor"), Side)
    elif "side" in entry:
        raise r.fail(f"{where}.side", "only wheel angles (beta_*) and torques (m_*) have a gear side")
    counts = None
    if unit == "counts":
        if "counts_per_rev" not in entry:
            raise r.fail(f"{where}.counts_per_rev", "required when unit is counts")
        counts = r.number(f"{where}.counts_per_rev", entry["counts_per_rev"], positive=True)
    elif "counts_per_rev" in entry:
        raise r.fail(f"{where}.counts_per_rev", f"only used with unit counts, not {unit!r}")
    kt = None
    if unit == "A":
        if "torque_constant" not in entry:
            raise r.fail(f"{where}.torque_constant", "required when unit is A (N m per A)")
        kt = r.number(f"{where}.torque_constant", entry["torque_constant"], positive=True)
    elif "torque_constant" in entry:
        raise r.fail(f"{where}.torque_constant", f"only used with unit A, not {unit!r}")
    return Signal(quantity, source, unit, sign, scale, offset, side, counts, kt)


def _segments(r: _Reader, value: Any, kind: InputKind) -> tuple[SegmentRange, ...] | SegmentColumn | None:
    if value is None:
        return None
    if isinstance(value, dict):
        if kind is not InputKind.TABLE:
            raise r.fail("segments", "a segment column exists only for tables; use a list of {name, start, end} for bags")
        r.unknown(value, {"column", "names"}, "segments.")
        if "column" not in value:
            raise r.fail("segments", "missing 'column'")
        names = r.mapping("segments.names", value.get("names", {}))
        for raw, name in names.items():
            if name not in SEGMENTS:
                raise r.fail(f"segments.names.{raw}", f"{name!r}: expected one of {list(SEGMENTS)}")
        return SegmentColumn(r.text("segments.column", value["column"]), tuple((str(k), str(v)) for k, v in names.items()))
    if not isinstance(value, list):
        raise r.fail("segments", "expected a list of {name, start, end} or {column, names}")
    ranges = []
    for i, item in enumerate(value):
        where = f"segments[{i}]"
        item = r.mapping(where, item)
        r.unknown(item, {"name", "start", "end"}, f"{where}.")
        for key in ("name", "start", "end"):
            if key not in item:
                raise r.fail(where, f"missing '{key}'")
        if item["name"] not in SEGMENTS:
            raise r.fail(f"{where}.name", f"{item['name']!r}: expected one of {list(SEGMENTS)}")
        start, end = r.number(f"{where}.start", item["start"]), r.number(f"{where}.end", item["end"])
        if end <= start:
            raise r.fail(where, f"end {end} <= start {start}: expected end > start")
        ranges.append(SegmentRange(item["name"], start, end))
    ranges.sort(key=lambda s: s.start)
    for a, b in zip(ranges, ranges[1:]):
        if b.start < a.end:
            raise r.fail("segments", f"{a.name} [{a.start}, {a.end}) overlaps {b.name} [{b.start}, {b.end})")
    return tuple(ranges)


def mapping_from_dict(data: Any, source: str | os.PathLike = "<mapping>") -> LogMapping:
    """Check a parsed mapping (the YAML structure described in ``docs/io.md``)."""
    r = _Reader(str(source))
    data = r.mapping("top level", data)
    r.unknown(data, _TOP_KEYS, "")
    if "input" not in data:
        raise r.fail("input", f"missing: expected one of {[k.value for k in InputKind]}")
    kind = r.choice("input", data["input"], InputKind)
    if kind is InputKind.TABLE:
        for key in ("topic", "stamps"):
            if key in data:
                raise r.fail(key, "only used with input ros2_bag")
    if kind is InputKind.ROS2_BAG and "time" in data:
        raise r.fail("time", "only used with input table (bags carry their own stamps)")
    topic = r.text("topic", data.get("topic", DEFAULT_TOPIC))
    stamps = r.choice("stamps", data.get("stamps", "header"), Stamps)
    rate = None if data.get("rate") is None else r.number("rate", data["rate"], positive=True)
    max_gap = None if data.get("max_gap") is None else r.number("max_gap", data["max_gap"], positive=True)
    i_G = None if data.get("i_G") is None else r.number("i_G", data["i_G"], positive=True)
    time = r.mapping("time", data.get("time", {}))
    r.unknown(time, {"column", "unit"}, "time.")
    time_column = r.text("time.column", time.get("column", "t"))
    time_unit = r.choice("time.unit", time.get("unit", "s"), TimeUnit)
    tol = r.number("coupling_tolerance", data.get("coupling_tolerance", DEFAULT_COUPLING_TOLERANCE), positive=True)
    if "signals" not in data:
        raise r.fail("signals", f"missing: expected a mapping from {list(REQUIRED_QUANTITIES)} to joints or columns")
    sig_data = r.mapping("signals", data["signals"])
    allowed = set(REQUIRED_QUANTITIES) | set(OPTIONAL_QUANTITIES)
    r.unknown(sig_data, allowed, "signals.")
    missing = [q for q in REQUIRED_QUANTITIES if q not in sig_data]
    if missing:
        raise r.fail("signals", f"missing {missing}: a mapping must give all of {list(REQUIRED_QUANTITIES)}")
    order = [q for q in (*REQUIRED_QUANTITIES, *OPTIONAL_QUANTITIES) if q in sig_data]
    signals = tuple(_signal(r, q, sig_data[q], kind) for q in order)
    if kind is InputKind.TABLE:
        used = {s.source for s in signals}
        if time_column in used:
            raise r.fail("time.column", f"{time_column!r} is also mapped as a signal")
    segments = _segments(r, data.get("segments"), kind)
    path = Path(source) if source != "<mapping>" else None
    return LogMapping(kind, signals, topic, stamps, rate, max_gap, time_column, time_unit, tol, segments, path, i_G)


def read_mapping(path: str | os.PathLike) -> LogMapping:
    """Read and check a mapping file (YAML). Unknown keys are errors naming the key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MappingError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    try:
        data = yaml.load(text, Loader=_LOADER)  # libyaml's safe loader: ~0.3 ms against ~5 ms
    except yaml.YAMLError as exc:
        raise MappingError(f"{path}: not valid YAML: {exc}") from exc
    return mapping_from_dict(data, path)
