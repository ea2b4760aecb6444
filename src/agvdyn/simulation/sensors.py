"""Sensors of the vehicle at T_s: quantized encoders, noisy steering angles, measured motor torques.

Every random number is drawn up front from one seeded ``numpy.random.Generator`` (vectorised),
so that a simulation is reproducible bit for bit and the compiled loop needs no random state.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorSettings:
    """Sensor models.

    encoder_counts : counts per motor revolution of the wheel encoders (4096: 1024 lines, quadrature);
        the wheel-side resolution is ``2 pi / (encoder_counts i_G)``.
    steering_counts : counts per revolution of the absolute steering encoders (14 bit).
    steering_noise : standard deviation of the steering-angle noise before quantization, rad.
    torque_noise : standard deviation of the motor-torque measurement noise (per sample), N m.
    torque_offset : standard deviation of the constant offset of each motor's torque measurement, N m.
    """

    encoder_counts: int = 4096
    steering_counts: int = 16384
    steering_noise: float = 5e-4
    torque_noise: float = 0.02
    torque_offset: float = 0.02

    def __post_init__(self) -> None:
        for key in ("encoder_counts", "steering_counts"):
            if not (isinstance(getattr(self, key), int) and getattr(self, key) >= 1):
                raise ValueError(f"sensor setting {key}={getattr(self, key)!r}: expected an integer >= 1")
        for key in ("steering_noise", "torque_noise", "torque_offset"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"sensor setting {key}={v!r}: expected a finite number >= 0")

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True, eq=False)
class SensorNoise:
    """Pre-drawn noise: steering ``(N, 2)`` rad, torque ``(N, 4)`` N m, torque offsets ``(4,)`` N m."""

    steering: np.ndarray
    torque: np.ndarray
    torque_offset: np.ndarray


def draw_noise(n_samples: int, settings: SensorSettings, rng: np.random.Generator) -> SensorNoise:
    """All sensor noise of a run of ``n_samples`` samples from ``rng`` (offsets first, then per sample)."""
    offset = rng.normal(0.0, settings.torque_offset, 4)
    steering = rng.normal(0.0, settings.steering_noise, (n_samples, 2))
    torque = rng.normal(0.0, settings.torque_noise, (n_samples, 4))
    return SensorNoise(steering, torque, offset)


from agvdyn.simulation._kernels import quantize, read_sensors  # noqa: E402,F401  (compiled)

__all__ = ["SensorSettings", "SensorNoise", "draw_noise", "quantize", "read_sensors"]
