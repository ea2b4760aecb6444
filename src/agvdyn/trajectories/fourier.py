"""Finite Fourier series of one coordinate (sec. 6.2 of the paper, Swevers et al. 1997)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn.trajectories.errors import TrajectoryError

__all__ = ["FourierSeries"]


@dataclass(frozen=True)
class FourierSeries:
    """Finite Fourier series of one coordinate (Swevers et al. 1997, as in sec. 6.2 of the paper).

    ``q(t) = q_0 + sum_k [a_k/(k w) sin(k w t) - b_k/(k w) cos(k w t)]``, k = 1..n, so that
    ``q_dot(t) = sum_k [a_k cos(k w t) + b_k sin(k w t)]``. Built with :meth:`at_rest` the series
    starts and ends (one period ``2 pi / w`` later) at ``start`` with zero velocity and
    acceleration.

    Parameters
    ----------
    base_frequency : w, rad/s; the segment lasts one period 2 pi / w.
    a, b : velocity amplitudes of the cosine and sine terms (unit of q per second).
    start : q(0) = q(2 pi / w).
    """

    base_frequency: float
    a: tuple[float, ...]
    b: tuple[float, ...]
    start: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.base_frequency) and self.base_frequency > 0):
            raise TrajectoryError(f"base_frequency={self.base_frequency!r}: expected a finite number > 0 rad/s")
        a, b = tuple(float(x) for x in self.a), tuple(float(x) for x in self.b)
        if len(a) != len(b) or not a:
            raise TrajectoryError(f"Fourier coefficients a ({len(a)}) and b ({len(b)}): expected the same number >= 1")
        if not all(math.isfinite(x) for x in a + b + (self.start,)):
            raise TrajectoryError(f"Fourier coefficients a={a}, b={b}, start={self.start}: expected finite numbers")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)

    @classmethod
    def at_rest(cls, base_frequency: float, a, b, start: float = 0.0, peak_velocity: float | None = None,
                peak_excursion: float | None = None) -> "FourierSeries":
        """Series that starts and ends at rest: the nearest coefficients (least squares) with
        ``sum a_k = 0`` (zero velocity) and ``sum k b_k = 0`` (zero acceleration) at t = 0,
        optionally scaled down so that ``max |q_dot| <= peak_velocity`` and
        ``max |q - start| <= peak_excursion`` (one of them reached)."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        k = np.arange(1, len(a) + 1, dtype=float)
        if a.shape != b.shape or a.ndim != 1:
            raise TrajectoryError(f"Fourier coefficients of shapes {a.shape}, {b.shape}: expected two equal 1-d lists")
        a = a - a.mean()
        b = b - k * (k @ b) / (k @ k)
        series = cls(base_frequency, tuple(a), tuple(b), start)
        if peak_velocity is None and peak_excursion is None:
            return series
        q, qd, _ = series.evaluate(np.linspace(0, series.period, 8001))
        peak_v, peak_q = np.max(np.abs(qd)), np.max(np.abs(q - start))
        if peak_v <= 0:
            raise TrajectoryError("Fourier coefficients give no motion: cannot scale them to a peak")
        scale = min(np.inf if peak_velocity is None else peak_velocity / peak_v,
                    np.inf if peak_excursion is None else peak_excursion / peak_q)
        return cls(base_frequency, tuple(a * scale), tuple(b * scale), start)

    @property
    def period(self) -> float:
        """2 pi / w, s."""
        return 2 * math.pi / self.base_frequency

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, q_dot, q_ddot)`` at the times t ``(N,)``.

        With ``z = exp(i w t)`` and ``c_k = a_k - i b_k``: ``q_dot = Re sum c_k z^k``,
        ``q = q_0 + Im sum c_k z^k / (k w)``, ``q_ddot = -Im sum k w c_k z^k``; the powers z^k come
        from a recurrence on z (one sine and one cosine per sample whatever the number of harmonics;
        they differ from sin(k w t), cos(k w t) by a few units in the last place).
        """
        t = np.asarray(t, dtype=float)
        w = self.base_frequency
        k = np.arange(1, len(self.a) + 1, dtype=float)
        a, b = np.array(self.a), np.array(self.b)
        phase = w * t
        z = np.empty(t.shape, dtype=complex)
        z.real, z.imag = np.cos(phase), np.sin(phase)
        zk = z.copy()
        pos, vel, acc = (np.zeros(t.shape, dtype=complex) for _ in range(3))
        for j, c in enumerate(a - 1j * b):
            if j:
                zk *= z
            pos += (c / (k[j] * w)) * zk
            vel += c * zk
            acc += (c * k[j] * w) * zk
        q0 = self.start + np.sum(b / (k * w))
        return q0 + pos.imag, vel.real, -acc.imag

    def to_dict(self) -> dict[str, Any]:
        return {"base_frequency": self.base_frequency, "a": list(self.a), "b": list(self.b), "start": self.start}

