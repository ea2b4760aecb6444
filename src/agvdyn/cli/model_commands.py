"""Commands on the model itself: identifiability (Table 1); the model of a parameter file (issue 30)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from agvdyn.cli._app import app, fail, platform_option
from agvdyn.cli._defaults import QR_TOLERANCE


def model_parameters_option(path: Path, paper):
    """What the feed-forward and the validation use of a ``--params`` file: ``paper`` (the file's
    :class:`~agvdyn.platform.Parameters`, as read before) when the file has no model beyond the paper,
    else its :class:`~agvdyn.model_spec.ModelParameters` (``model:`` block and extra parameters,
    :func:`agvdyn.model_file.read_model_parameters`); a bad block is a named error."""
    from agvdyn.model_file import read_model_parameters

    try:
        model = read_model_parameters(path)
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc
    return paper if model.spec.is_paper and model.delay_s == 0.0 else model


def _format_row(row) -> str:
    groups = []
    for rep in row.identifiable:
        members = [m for m in row.groups[rep] if m != rep]
        groups.append(rep + (f" (+{', '.join(members)})" if members else ""))
    return f"{'{' + ', '.join(m.label for m in row.modes) + '}':<14} {row.rank:>4}   {'  '.join(groups)}"


@app.command()
def identifiability(
    modes: Optional[str] = typer.Option(None, help="Comma-separated modes, e.g. 1,2s,4 (1, 2, 3, 4, 2s = straight). "
                                                   "Without it: the rows of Table 1."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON (keys: docs/cli.md)."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the built-in prototype."),
    tolerance: float = typer.Option(QR_TOLERANCE, help="Relative |R_ii| below which a parameter is dependent."),
    samples: int = typer.Option(400, help="Random samples per mode."),
    seed: int = typer.Option(0, help="Seed of the random motions."),
) -> None:
    """Base parameters of motion modes by QR decomposition (paper sec. 6.1, Table 1)."""
    from agvdyn.identifiability import base_parameters, parse_modes, table1
    from agvdyn.platform import PARAMETER_NAMES

    geom = platform_option(platform)
    try:
        if modes is not None:
            rows = [base_parameters(geom, parse_modes(modes), n_samples=samples, seed=seed, tolerance=tolerance)]
        else:
            rows = table1(geom, n_samples=samples, seed=seed, tolerance=tolerance)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    if as_json:
        data = rows[0].to_dict() if modes is not None else [r.to_dict() for r in rows]
        typer.echo(json.dumps(data, indent=2))
        return
    typer.echo(f"Linearly independent parameters (QR, relative tolerance {tolerance:g}, platform {geom.name})")
    typer.echo(f"{'modes':<14} {'rank':>4}   base parameters (regrouped parameters)")
    for row in rows:
        typer.echo(_format_row(row))
    typer.echo(f"parameter order of eq. (18): {', '.join(PARAMETER_NAMES)}")
