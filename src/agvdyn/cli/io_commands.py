"""Command ``agvdyn convert``: any input (table, ROS 2 bag) -> our log schema."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from agvdyn.cli._app import app, fail, platform_option
from agvdyn.cli._defaults import STOP_TOLERANCE
from agvdyn.cli._outputs import LOG_AND_SIDECAR, log_inputs, refuse_overwrite, sidecar_of


@app.command()
def convert(
    input: Path = typer.Argument(..., help="Log in our schema (.parquet/.csv), any CSV/Parquet table, or a ROS 2 bag (directory, .db3, .mcap)."),
    out: Path = typer.Option(..., "--out", "-o", help="Log to write in our schema (.parquet or .csv); sidecar <out>.yaml records the conversion."),
    mapping: Optional[Path] = typer.Option(None, help="Mapping file (YAML) naming joints/columns and units; see examples/mappings/."),
    platform: Optional[Path] = typer.Option(
        None, help="Platform file (YAML) for the gear ratio i_G of motor-side encoders and wheel-side torques; "
        "without it the mapping must declare i_G: when such signals are mapped (no ratio is assumed)."),
    stop_tolerance: float = typer.Option(
        STOP_TOLERANCE, help="rad beyond the steering stops +-pi/2 that is clipped to the stop (sensor noise); further out is an error."),
) -> None:
    """Convert a ROS 2 bag or a table to our log schema, so that you can look at what was understood."""
    from agvdyn.io import LogError, MappingError, load_log, write_log
    from agvdyn.platform import PlatformFileError

    refuse_overwrite({"--out": out, "sidecar of --out": sidecar_of(out)},
                     {**log_inputs("INPUT", [input]), "--mapping": mapping, "--platform": platform}, LOG_AND_SIDECAR)

    _LOAD_ERRORS = (LogError, MappingError, PlatformFileError)
    geom = platform_option(platform) if platform is not None else None
    try:
        log = load_log(input, mapping, geom, stop_tolerance=stop_tolerance)
        sidecar = dict(log.sidecar)
        if geom is not None:
            sidecar["platform"] = geom.to_dict()  # the platform given (its i_G is in sidecar['conversion'])
        if any(log.clipped.values()):
            sidecar["clipped_to_stops"] = dict(log.clipped)  # the written angles are clipped
        written = write_log(out, log.frame, sidecar)
    except _LOAD_ERRORS as exc:
        raise fail(str(exc)) from exc
    except ValueError as exc:  # a bad option value (for example a negative --stop-tolerance)
        raise fail(str(exc)) from exc
    except OSError as exc:
        raise fail(f"{out}: cannot be written: {exc}") from exc
    typer.echo(f"wrote {written} ({log.n_samples:,} samples, {log.duration:.3f} s at {log.rate:.6g} Hz) and {written}.yaml")
    conv = log.sidecar.get("conversion", {})
    if conv.get("method"):
        typer.echo(f"resampled at {conv['rate']:g} Hz: {conv['method']}")
    if conv.get("i_G") is not None:
        typer.echo(f"gear ratio i_G = {conv['i_G']:g} (from the {conv['i_G_source']})")
    for note in conv.get("notes", []) or []:
        typer.echo(f"note: {note}")
    if any(log.clipped.values()):
        counts = ", ".join(f"{n} rows of {col}" for col, n in log.clipped.items())
        typer.echo(f"note: clipped to the steering stops +-pi/2 (within {stop_tolerance:g} rad): {counts}")
    gaps = log.gaps()
    if gaps:
        listed = ", ".join(f"{a:.6g} s to {b:.6g} s" for a, b in gaps[:5]) + (f" and {len(gaps) - 5} more" if len(gaps) > 5 else "")
        typer.echo(f"note: {len(gaps):,} time gap(s) (dropouts; identification uses the {len(gaps) + 1:,} continuous stretches): {listed}")
