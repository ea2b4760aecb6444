"""Errors of the trajectory stage: every message names the source and the offending value."""
from __future__ import annotations

__all__ = ["TrajectoryError", "LimitError"]


class TrajectoryError(ValueError):
    """A trajectory that cannot be planned or read; the message names the source and the value."""


class LimitError(TrajectoryError):
    """A planned trajectory breaks a limit; the message names the limit, segment, time and value."""

