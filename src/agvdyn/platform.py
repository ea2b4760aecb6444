"""Platform geometry, the 11 dynamic parameters of eq. (18), and their YAML/JSON files.

Conventions follow ``shared/PLATFORM.md``: chassis frame at the centre of the rectangle of
the steering axes, wheel order ``fl, rl, fr, rr``, parameter order of eq. (18).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agvdyn._files import write_text_atomically

#: Width of the tanh Coulomb friction model ``d_c tanh(velocity / EPSILON)``, rad/s.
EPSILON = 0.01
#: Sampling time of the paper's logs, s.
SAMPLE_TIME = 2e-3
#: Wheel order of every per-wheel array.
WHEELS = ("fl", "rl", "fr", "rr")
#: Names of the 11 dynamic parameters in the order of eq. (18).
PARAMETER_NAMES = ("C_l", "d_vl", "d_cl", "C_r", "d_vr", "d_cr", "m_ch", "C_ch", "d_vw", "d_cw", "B_w")
PARAMETER_UNITS = {
    "C_l": "kg m^2", "d_vl": "N m s/rad", "d_cl": "N m",
    "C_r": "kg m^2", "d_vr": "N m s/rad", "d_cr": "N m",
    "m_ch": "kg", "C_ch": "kg m^2", "d_vw": "N m s/rad", "d_cw": "N m", "B_w": "kg m^2",
}


class PlatformFileError(ValueError):
    """A platform or parameter file that cannot be used; the message names file and key."""


@dataclass(frozen=True)
class Geometry:
    """Geometry of the quasi-omnidirectional platform (PLATFORM.md, Fig. 2).

    l, b: distances of the steering axes along x and y (m); a: offset of the contact point
    from the steering axis along the axle, positive outboard (m); r: wheel radius (m);
    i_G: gear ratio, wheel torque = i_G * motor torque.
    """

    l: float
    b: float
    a: float
    r: float
    i_G: float
    name: str = "prototype"

    def __post_init__(self) -> None:
        for key in ("l", "b", "r", "i_G"):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"geometry {key}={value!r}: expected a finite number > 0")
        if not isinstance(self.a, (int, float)) or not math.isfinite(self.a):
            raise ValueError(f"geometry a={self.a!r}: expected a finite number")
        if abs(self.a) >= min(self.l, self.b) / 2:
            raise ValueError(
                f"geometry a={self.a!r}: expected |a| < min(l, b)/2 = {min(self.l, self.b) / 2}"
            )
        for key in ("l", "b", "a", "r", "i_G"):
            object.__setattr__(self, key, float(getattr(self, key)))

    @property
    def steering_axes(self) -> np.ndarray:
        """Positions of the steering axes ``(4, 2)`` in wheel order fl, rl, fr, rr."""
        hl, hb = self.l / 2, self.b / 2
        return np.array([[hl, hb], [-hl, hb], [hl, -hb], [-hl, -hb]])

    @property
    def side_sign(self) -> np.ndarray:
        """+1 for the left wheels, -1 for the right wheels (direction of the offset ``a``)."""
        return np.array([1.0, 1.0, -1.0, -1.0])

    @property
    def heading_sign(self) -> np.ndarray:
        """Wheel heading = heading_sign * alpha of its side (rear wheels mirrored)."""
        return np.array([1.0, -1.0, 1.0, -1.0])

    @property
    def rotation_angle(self) -> float:
        """arctan(l/b): |alpha| of both sides in pure rotation (mode 4, eq. 9)."""
        return math.atan2(self.l, self.b)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "l": self.l, "b": self.b, "a": self.a, "r": self.r, "i_G": self.i_G}

    def same_shape(self, other: "Geometry", rtol: float = 1e-9) -> bool:
        """True when l, b, a, r, i_G agree (names may differ)."""
        return all(math.isclose(getattr(self, k), getattr(other, k), rel_tol=rtol, abs_tol=1e-12)
                   for k in ("l", "b", "a", "r", "i_G"))

    def describe(self) -> str:
        """One line for messages: name and the five numbers."""
        return f"{self.name}: l={self.l:g} m, b={self.b:g} m, a={self.a:g} m, r={self.r:g} m, i_G={self.i_G:g}"


#: Default geometry of the prototype, assumed in PLATFORM.md (the paper does not publish it).
PROTOTYPE = Geometry(l=1.2, b=0.8, a=0.05, r=0.1, i_G=25.0, name="prototype")


@dataclass(frozen=True)
class Parameters:
    """The 11 dynamic parameters p of eq. (18), SI units (see PARAMETER_UNITS)."""

    C_l: float
    d_vl: float
    d_cl: float
    C_r: float
    d_vr: float
    d_cr: float
    m_ch: float
    C_ch: float
    d_vw: float
    d_cw: float
    B_w: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float, np.floating)) or not math.isfinite(value):
                raise ValueError(f"parameter {f.name}={value!r}: expected a finite number")
            object.__setattr__(self, f.name, float(value))

    def to_vector(self) -> np.ndarray:
        """Parameter vector p in the order of eq. (18)."""
        return np.array([getattr(self, n) for n in PARAMETER_NAMES])

    @classmethod
    def from_vector(cls, p: np.ndarray) -> "Parameters":
        p = np.asarray(p, dtype=float)
        if p.shape != (len(PARAMETER_NAMES),):
            raise ValueError(f"parameter vector of shape {p.shape}: expected ({len(PARAMETER_NAMES)},)")
        return cls(*p.tolist())

    def to_dict(self) -> dict[str, float]:
        return {n: getattr(self, n) for n in PARAMETER_NAMES}

    def replace(self, **changes: float) -> "Parameters":
        unknown = set(changes) - set(PARAMETER_NAMES)
        if unknown:
            raise ValueError(f"unknown parameter names {sorted(unknown)}: expected some of {PARAMETER_NAMES}")
        return Parameters(**{**self.to_dict(), **changes})


#: Table 2 of the paper with B_w = 0.121 kg m^2: the default "true" parameters.
PAPER_PARAMETERS = Parameters(
    C_l=0.3342, d_vl=4.4649, d_cl=12.9458, C_r=0.4501, d_vr=2.4820, d_cr=17.1071,
    m_ch=842.0684, C_ch=286.5955, d_vw=0.7316, d_cw=3.9656, B_w=0.121,
)
#: Standard deviations of Table 2 (B_w was not estimated).
PAPER_STD = {
    "C_l": 0.0685, "d_vl": 0.6807, "d_cl": 0.7664, "C_r": 0.0641, "d_vr": 0.6864,
    "d_cr": 0.8061, "m_ch": 0.9934, "C_ch": 1.1835, "d_vw": 0.0062, "d_cw": 0.0125,
}
#: cond(Theta_1^T Theta_1) reported in sec. 7.
PAPER_CONDITION_NUMBER = 11.56


@dataclass(frozen=True)
class ParameterFile:
    """Contents of a parameter file: values, optional standard deviations and identification facts."""

    parameters: Parameters
    std: dict[str, float] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()
    condition_number: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: The vehicle the parameters belong to (key ``platform``), None when the file names none.
    geometry: Geometry | None = None

    def __post_init__(self) -> None:
        for name in (*self.std, *self.fixed):
            if name not in PARAMETER_NAMES:
                raise ValueError(f"unknown parameter name {name!r}: expected one of {PARAMETER_NAMES}")

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"parameters": {}}
        for name in PARAMETER_NAMES:
            entry: dict[str, Any] = {"value": getattr(self.parameters, name), "unit": PARAMETER_UNITS[name]}
            if name in self.std:
                entry["std"] = float(self.std[name])
            entry["fixed"] = name in self.fixed
            out["parameters"][name] = entry
        out["condition_number"] = None if self.condition_number is None else float(self.condition_number)
        out["fixed"] = list(self.fixed)
        if self.geometry is not None:
            out["platform"] = self.geometry.to_dict()
        out.update({k: v for k, v in self.extra.items() if k != "platform" or self.geometry is None})
        return out


def _load_mapping(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise PlatformFileError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    except UnicodeDecodeError as exc:
        raise PlatformFileError(f"{path}: not a text file (not UTF-8 at byte {exc.start}): expected YAML or JSON") from exc
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (yaml.YAMLError, json.JSONDecodeError) as exc:
        raise PlatformFileError(f"{path}: not valid {'JSON' if path.suffix == '.json' else 'YAML'}: {exc}") from exc
    if not isinstance(data, dict):
        raise PlatformFileError(f"{path}: expected a mapping at the top level, found {type(data).__name__}")
    return data


def _number(path: Path, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PlatformFileError(f"{path}: {key}={value!r}: expected a number")
    return float(value)


def read_platform(path: str | os.PathLike) -> Geometry:
    """Read a platform file (YAML with l, b, a, r, i_G in SI units and an optional name)."""
    path = Path(path)
    data = _load_mapping(path)
    missing = [k for k in ("l", "b", "a", "r", "i_G") if k not in data]
    if missing:
        raise PlatformFileError(f"{path}: missing keys {missing}: a platform file needs l, b, a, r, i_G (SI units)")
    values = {k: _number(path, k, data[k]) for k in ("l", "b", "a", "r", "i_G")}
    try:
        return Geometry(**values, name=str(data.get("name", path.stem)))
    except ValueError as exc:
        raise PlatformFileError(f"{path}: {exc}") from exc


def write_platform(path: str | os.PathLike, geometry: Geometry) -> Path:
    """Write a platform file atomically."""
    return write_text_atomically(path, yaml.safe_dump(geometry.to_dict(), sort_keys=False))


def read_parameters(path: str | os.PathLike) -> ParameterFile:
    """Read a parameter file (YAML or JSON): for each name a ``value`` (and ``std``).

    Accepts ``{parameters: {C_l: {value: .., std: ..}, ...}, condition_number, fixed}`` or the
    flat form ``{C_l: {value: ..}, ...}`` / ``{C_l: 0.33, ...}``.
    """
    path = Path(path)
    data = _load_mapping(path)
    table = data.get("parameters", data)
    if not isinstance(table, dict):
        raise PlatformFileError(f"{path}: 'parameters' must be a mapping of parameter names")
    missing = [n for n in PARAMETER_NAMES if n not in table]
    if missing:
        raise PlatformFileError(f"{path}: missing parameters {missing}: expected all of {list(PARAMETER_NAMES)}")
    values, std = {}, {}
    for name in PARAMETER_NAMES:
        entry = table[name]
        if isinstance(entry, dict):
            if "value" not in entry:
                raise PlatformFileError(f"{path}: parameter {name} has no 'value'")
            values[name] = _number(path, f"{name}.value", entry["value"])
            if entry.get("std") is not None:
                std[name] = _number(path, f"{name}.std", entry["std"])
        else:
            values[name] = _number(path, name, entry)
    fixed = data.get("fixed") or [n for n in PARAMETER_NAMES if isinstance(table[n], dict) and table[n].get("fixed")]
    if not isinstance(fixed, list) or any(n not in PARAMETER_NAMES for n in fixed):
        raise PlatformFileError(f"{path}: fixed={fixed!r}: expected a list of parameter names from {list(PARAMETER_NAMES)}")
    cond = data.get("condition_number")
    geometry = None if data.get("platform") is None else _geometry_entry(path, data["platform"])
    try:
        params = Parameters(**values)
        return ParameterFile(params, std, tuple(fixed), None if cond is None else _number(path, "condition_number", cond),
                             geometry=geometry)
    except ValueError as exc:
        raise PlatformFileError(f"{path}: {exc}") from exc


def _geometry_entry(path: Path, entry: Any) -> Geometry:
    """The ``platform`` entry of a parameter file as a Geometry."""
    keys = ("l", "b", "a", "r", "i_G")
    if not isinstance(entry, dict) or any(k not in entry for k in keys):
        raise PlatformFileError(f"{path}: platform: expected a mapping with {list(keys)}, found {entry!r}")
    values = {k: _number(path, f"platform.{k}", entry[k]) for k in keys}
    try:
        return Geometry(**values, name=str(entry.get("name", "platform")))
    except ValueError as exc:
        raise PlatformFileError(f"{path}: platform: {exc}") from exc


def platform_of_parameters(content: ParameterFile, override: Geometry | None = None) -> tuple[Geometry, str | None]:
    """The vehicle to use with a parameter file, and a warning or None.

    ``override`` (a ``--platform``) wins, with a warning when its geometry differs from the one
    stored in the file; else the file's platform; else the prototype (with a warning: the file
    does not say which vehicle its parameters belong to).
    """
    stored = content.geometry
    if override is not None:
        if stored is not None and not stored.same_shape(override):
            return override, (f"the platform given ({override.describe()}) differs from the one stored in the "
                              f"parameter file ({stored.describe()}); using the one given")
        return override, None
    if stored is not None:
        return stored, None
    return PROTOTYPE, "the parameter file names no platform: using the built-in prototype"


def write_parameters(path: str | os.PathLike, content: ParameterFile | Parameters) -> Path:
    """Write a parameter file atomically, as JSON when the suffix is .json, else YAML."""
    if isinstance(content, Parameters):
        content = ParameterFile(content)
    data = content.to_dict()
    text = json.dumps(data, indent=2) if str(path).lower().endswith(".json") else yaml.safe_dump(data, sort_keys=False)
    return write_text_atomically(path, text)
