"""agvdyn: dynamics, simulation, identification and feed-forward for motion-mode-changing AGVs."""
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, Geometry, Parameters

__all__ = ["Geometry", "Parameters", "PARAMETER_NAMES", "PAPER_PARAMETERS", "PROTOTYPE"]
__version__ = "0.1.0"
