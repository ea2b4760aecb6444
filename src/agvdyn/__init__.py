"""agvdyn: dynamics, simulation, identification and feed-forward for motion-mode-changing AGVs."""
__all__ = ["Geometry", "Parameters", "PARAMETER_NAMES", "PAPER_PARAMETERS", "PROTOTYPE"]


def __getattr__(name: str):
    """The names of ``__all__`` from agvdyn.platform on first use: importing agvdyn (and the CLI, whose
    ``--help`` must answer fast) does not import numpy."""
    if name in __all__:
        from agvdyn import platform

        return getattr(platform, name)
    raise AttributeError(f"module 'agvdyn' has no attribute {name!r}")

try:  # the installed distribution's version (pyproject.toml), one source of truth
    from importlib.metadata import PackageNotFoundError as _NotFound, version as _version

    __version__ = _version("agvdyn")
except _NotFound:  # running from a source tree that is not installed
    __version__ = "0+unknown"
