"""The typer application every command module registers on."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from agvdyn.platform import PROTOTYPE, Geometry, PlatformFileError, read_platform

app = typer.Typer(
    name="agvdyn",
    help="Model, simulate and identify motion-mode-changing wheeled platforms (Pucher, Gattringer, Mueller).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def fail(message: str, code: int = 2) -> "typer.Exit":
    """Print an error for the user and return the Exit to raise."""
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    return typer.Exit(code)


def platform_option(path: Optional[Path]) -> Geometry:
    """The platform of a --platform option, or the built-in prototype; a bad file is a clean error."""
    if path is None:
        return PROTOTYPE
    try:
        return read_platform(path)
    except PlatformFileError as exc:
        raise fail(str(exc)) from exc
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise fail(f"{path}: cannot be read as a platform file: {exc}") from exc


@app.callback()
def _root() -> None:
    """agvdyn: model, simulate and identify motion-mode-changing wheeled platforms."""
