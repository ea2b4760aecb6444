"""Settings of a simulation run (plant, controller, sensors, limits, slip scenario) and their
YAML file (docs/simulation.md)."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agvdyn.platform import SAMPLE_TIME
from agvdyn.simulation.controller import ControllerSettings
from agvdyn.simulation.payload import PayloadEvent, payload_from_list
from agvdyn.simulation.plant import PlantSettings
from agvdyn.simulation.sensors import SensorSettings
from agvdyn.simulation.slip import SlipSettings
from agvdyn.trajectories import Limits

__all__ = ["SimulationSettings", "settings_from_dict", "read_settings"]


@dataclass(frozen=True)
class SimulationSettings:
    """Everything about a simulation run besides platform, parameters and seed.

    ``check_limits``: refuse (LimitError) a trajectory whose planned velocities, accelerations
    or feed-forward torques break ``limits`` before simulating it. ``slip``: the wheel-slip
    scenario (low-friction patches, torque bursts; none by default, see :mod:`agvdyn.simulation.slip`).
    """

    plant: PlantSettings = field(default_factory=PlantSettings)
    controller: ControllerSettings = field(default_factory=ControllerSettings)
    sensors: SensorSettings = field(default_factory=SensorSettings)
    limits: Limits = field(default_factory=Limits)
    check_limits: bool = True
    sample_time: float = SAMPLE_TIME
    slip: SlipSettings = field(default_factory=SlipSettings)
    payload: tuple[PayloadEvent, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.payload, (list, tuple)) or not all(isinstance(e, PayloadEvent) for e in self.payload):
            raise ValueError(f"payload={self.payload!r}: expected a list of PayloadEvent (agvdyn.simulation.payload)")
        object.__setattr__(self, "payload", tuple(sorted(self.payload, key=lambda e: e.t)))
        if not (math.isfinite(self.sample_time) and self.sample_time > 0):
            raise ValueError(f"sample_time={self.sample_time!r}: expected > 0 s")
        if not isinstance(self.slip, SlipSettings):
            raise ValueError(f"slip={self.slip!r}: expected a SlipSettings (see agvdyn.simulation.slip)")

    def to_dict(self) -> dict[str, Any]:
        return {
            "plant": self.plant.to_dict(), "controller": self.controller.to_dict(),
            "sensors": self.sensors.to_dict(), "limits": dict(self.limits.__dict__),
            "check_limits": self.check_limits, "sample_time": self.sample_time, "slip": self.slip.to_dict(),
        } | ({"payload": [e.to_dict() for e in self.payload]} if self.payload else {})


_SETTING_GROUPS = {"plant": PlantSettings, "controller": ControllerSettings, "sensors": SensorSettings,
                   "limits": Limits}


def settings_from_dict(data: dict[str, Any], source: str = "<settings>") -> SimulationSettings:
    """SimulationSettings from a mapping ``{plant: {...}, controller: {...}, sensors: {...}, limits: {...},
    slip: {patches: [...], bursts: [...]}, check_limits: bool}``; unset keys keep their defaults,
    unknown keys are an error naming them."""
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a mapping at the top level")
    unknown = set(data) - set(_SETTING_GROUPS) - {"check_limits", "sample_time", "slip", "payload"}
    if unknown:
        raise ValueError(f"{source}: unknown keys {sorted(unknown)}: expected some of "
                         f"{sorted([*_SETTING_GROUPS, 'check_limits', 'payload', 'sample_time', 'slip'])}")
    groups: dict[str, Any] = {}
    for key, cls in _SETTING_GROUPS.items():
        values = data.get(key) or {}
        if not isinstance(values, dict):
            raise ValueError(f"{source}: {key}: expected a mapping")
        allowed = set(cls.__dataclass_fields__)
        bad = set(values) - allowed
        if bad:
            raise ValueError(f"{source}: {key}: unknown keys {sorted(bad)}: expected some of {sorted(allowed)}")
        if "wheel_radius_error" in values:
            values = {**values, "wheel_radius_error": tuple(values["wheel_radius_error"])}
        try:
            groups[key] = cls(**values)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: {key}: {exc}") from exc
    extra = {k: data[k] for k in ("check_limits", "sample_time") if k in data}
    slip = SlipSettings.from_dict(data.get("slip"), source)
    return SimulationSettings(**groups, **extra, slip=slip, payload=payload_from_list(data.get("payload"), source))


def read_settings(path: str | os.PathLike) -> SimulationSettings:
    """Simulation settings from a YAML file (see :func:`settings_from_dict`); the file is only read."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot be read as YAML: {exc}") from exc
    return settings_from_dict(data or {}, str(path))
