"""agvdyn: dynamics, simulation, identification and feed-forward for motion-mode-changing AGVs."""
__all__ = ["Geometry", "Parameters", "PARAMETER_NAMES", "PAPER_PARAMETERS", "PROTOTYPE"]


def __getattr__(name: str):
    """The names of ``__all__`` from agvdyn.platform on first use: importing agvdyn (and the CLI, whose
    ``--help`` must answer fast) does not import numpy. ``__version__`` is looked up on first use too:
    importlib.metadata costs 40-90 ms of every command's start-up."""
    if name in __all__:
        from agvdyn import platform

        return getattr(platform, name)
    if name == "__version__":
        global __version__
        __version__ = _installed_version()
        return __version__
    raise AttributeError(f"module 'agvdyn' has no attribute {name!r}")


def _installed_version() -> str:
    """The installed distribution's version (pyproject.toml), one source of truth."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("agvdyn")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "0+unknown"
