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
    torque_delay : seconds the logged torque columns lag the angles (bus cycles, filters; issue 30,
        ``delay_s`` of :mod:`agvdyn.model_spec`): the torque reading logged at t (applied torque,
        offset and noise) was taken at ``t - torque_delay`` (:func:`delayed_torques`); the controller
        does not use it, so the motion is unchanged. On top of the zero-order hold of the drive (the
        sidecar's ``torque_lead``).
    """

    encoder_counts: int = 4096
    steering_counts: int = 16384
    steering_noise: float = 5e-4
    torque_noise: float = 0.02
    torque_offset: float = 0.02
    torque_delay: float = 0.0

    def __post_init__(self) -> None:
        for key in ("encoder_counts", "steering_counts"):
            if not (isinstance(getattr(self, key), int) and getattr(self, key) >= 1):
                raise ValueError(f"sensor setting {key}={getattr(self, key)!r}: expected an integer >= 1")
        for key in ("steering_noise", "torque_noise", "torque_offset", "torque_delay"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"sensor setting {key}={v!r}: expected a finite number >= 0")

    def to_dict(self) -> dict:
        """The settings as plain data; ``torque_delay`` only when set (older files unchanged)."""
        out = dict(self.__dict__)
        if out["torque_delay"] == 0.0:
            del out["torque_delay"]
        return out


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


def delayed_torques(measured: np.ndarray, delay_samples: float) -> np.ndarray:
    """The torque log ``measured`` (N, ...) lagging by ``delay_samples`` >= 0 sample periods: row k is
    the measurement at ``k - delay_samples``, linearly interpolated between its two neighbours (a whole
    number of samples: an exact shift); rows before the first measurement hold the first row.

    >>> delayed_torques(np.array([0.0, 1.0, 2.0, 3.0]), 1.5)
    array([0. , 0. , 0.5, 1.5])
    """
    if not (math.isfinite(delay_samples) and delay_samples >= 0):
        raise ValueError(f"torque delay of {delay_samples!r} samples: expected a finite number >= 0")
    measured = np.asarray(measured, dtype=float)
    whole = math.floor(delay_samples + 1e-9)
    frac = max(delay_samples - whole, 0.0)
    n = measured.shape[0]
    index = np.arange(n) - whole
    later = measured[np.clip(index, 0, n - 1)]
    if frac < 1e-9:
        return later
    earlier = measured[np.clip(index - 1, 0, n - 1)]
    return (1.0 - frac) * later + frac * earlier


from agvdyn.simulation._kernels import quantize, read_sensors  # noqa: E402,F401  (compiled)

__all__ = ["SensorSettings", "SensorNoise", "draw_noise", "delayed_torques", "quantize", "read_sensors"]
