"""Commands on logs: ``agvdyn convert`` (any input -> our schema) and ``agvdyn inspect``."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from agvdyn.cli._app import app, fail, platform_option
from agvdyn.io import STOP_TOLERANCE, LogError, MappingError, load_log, sidecar_platform, write_log
from agvdyn.io.summary import summarize_log
from agvdyn.kinematics import MODE_TOLERANCE
from agvdyn.platform import PlatformFileError

_LOAD_ERRORS = (LogError, MappingError, PlatformFileError)


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
    geom = platform_option(platform) if platform is not None else None
    if out.resolve() == input.resolve():
        raise fail(f"{out}: the output would overwrite the input; choose another --out")
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
    typer.echo(f"wrote {written} ({log.n_samples} samples, {log.duration:.3f} s at {log.rate:.6g} Hz) and {written}.yaml")
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
        typer.echo(f"note: {len(gaps)} time gap(s) (dropouts; identification uses the {len(gaps) + 1} continuous stretches): {listed}")


@app.command()
def inspect(
    log_path: Path = typer.Argument(..., metavar="LOG", help="Log, table or ROS 2 bag (with --mapping)."),
    mapping: Optional[Path] = typer.Option(None, help="Mapping file for tables with other names/units and for bags."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the built-in prototype."),
    tolerance: float = typer.Option(MODE_TOLERANCE, help="Tolerance of the mode detection (rad), eq. (9)."),
    min_duration: float = typer.Option(0.05, help="Mode runs shorter than this (s) are merged into the preceding run in the list (0: list every run)."),
    max_rows: int = typer.Option(40, help="Longest list of mode runs printed; the rest is counted."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Print duration, rate, segments and the motion modes detected over time."""
    geom = platform_option(platform)
    try:
        log = load_log(log_path, mapping, geom)
        if platform is None:  # a log that records its platform is inspected with it
            geom = sidecar_platform(log) or geom
        summary = summarize_log(log, geom, tolerance=tolerance, min_duration=min_duration)
    except _LOAD_ERRORS as exc:
        raise fail(str(exc)) from exc
    except ValueError as exc:
        raise fail(str(exc)) from exc
    if as_json:
        typer.echo(json.dumps(summary.to_dict(), indent=2))
        return
    console = Console(highlight=False)
    console.print(f"[bold]{log_path}[/bold]")
    console.print(f"samples   {summary.n_samples}")
    console.print(f"time      {summary.t_start:.6g} s .. {summary.t_end:.6g} s (duration {summary.duration:.3f} s)")
    console.print(f"rate      {summary.rate:.6g} Hz (median sample time {summary.sample_time * 1e3:.4g} ms)")
    console.print(f"platform  {geom.name} (l={geom.l:g} m, b={geom.b:g} m, i_G={geom.i_G:g})")
    for note in summary.notes:
        console.print(f"note      {note}")
    if summary.segments:
        table = Table(title="segments", title_justify="left")
        for col in ("name", "start (s)", "end (s)", "duration (s)"):
            table.add_column(col, justify="left" if col == "name" else "right")
        for s in summary.segments:
            table.add_row(s.name, f"{s.t_start:.3f}", f"{s.t_end:.3f}", f"{s.duration:.3f}")
        console.print(table)
    else:
        console.print("segments  none (no segment column)")
    title = f"motion modes detected from alpha (eq. 9, tolerance {summary.tolerance:g} rad)"
    if summary.min_duration > 0 and summary.n_detected_runs > len(summary.modes):
        title += (f"; {summary.n_detected_runs} detected runs, those shorter than {summary.min_duration:g} s "
                  "merged into the preceding run")
    table = Table(title=title, title_justify="left")
    for col in ("mode", "start (s)", "end (s)", "duration (s)"):
        table.add_column(col, justify="left" if col == "mode" else "right")
    for m in summary.modes[:max_rows]:
        table.add_row(f"{m.mode.label} {m.mode.name.lower()}", f"{m.t_start:.3f}", f"{m.t_end:.3f}", f"{m.duration:.3f}")
    console.print(table)
    if len(summary.modes) > max_rows:
        console.print(f"... {len(summary.modes) - max_rows} more runs (--max-rows, or --json for all)")
    totals = ", ".join(f"{k}: {v:.3f} s" for k, v in sorted(summary.mode_time.items()))
    console.print(f"time per mode (rows x sample time)  {totals}")
