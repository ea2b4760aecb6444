"""agvdyn: dynamics, simulation, identification and feed-forward for motion-mode-changing AGVs."""
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Geometry, Parameters

__all__ = ["Geometry", "Parameters", "PARAMETER_NAMES", "PAPER_PARAMETERS", "PROTOTYPE"]

try:  # the installed distribution's version (pyproject.toml), one source of truth
    from importlib.metadata import PackageNotFoundError as _NotFound, version as _version

    __version__ = _version("agvdyn")
except _NotFound:  # running from a source tree that is not installed
    __version__ = "0+unknown"
