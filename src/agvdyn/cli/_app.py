"""The typer application every command module registers on."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

app = typer.Typer(
    name="agvdyn",
    help="Model, simulate and identify motion-mode-changing wheeled platforms (Pucher, Gattringer, Mueller).\n\n"
         "Exit codes: 0 ok; 1 refused for data quality (identify, report, inspect --strict); 2 bad usage or "
         "input. --json prints a command's result as JSON (keys: docs/cli.md).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def fail(message: str, code: int = 2) -> "typer.Exit":
    """Print an error for the user and return the Exit to raise."""
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    return typer.Exit(code)


def numbers_by_name(option: str, items, allowed) -> dict[str, float]:
    """``NAME=VALUE`` items of a repeatable option as ``{name: finite float}``; a bad item is a clean
    error naming it and what was expected."""
    import math

    allowed = list(allowed)
    out = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or name not in allowed:
            raise fail(f"{option} {item!r}: expected NAME=VALUE with NAME one of {', '.join(allowed)}")
        try:
            out[name] = float(value)
        except ValueError:
            raise fail(f"{option} {item!r}: {value!r} is not a number") from None
        if not math.isfinite(out[name]):
            raise fail(f"{option} {item!r}: expected a finite number")
    return out


def platform_option(path: Optional[Path]) -> Geometry:
    """The platform of a --platform option, or the built-in prototype; a bad file is a clean error."""
    from agvdyn.platform import PROTOTYPE, PlatformFileError, read_platform

    if path is None:
        return PROTOTYPE
    try:
        return read_platform(path)
    except PlatformFileError as exc:
        raise fail(str(exc)) from exc
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise fail(f"{path}: cannot be read as a platform file: {exc}") from exc


def _print_version(value: bool) -> None:
    if value:
        from agvdyn import __version__

        typer.echo(f"agvdyn {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                 help="Print the version of agvdyn and exit."),
) -> None:
    """agvdyn: model, simulate and identify motion-mode-changing wheeled platforms."""
