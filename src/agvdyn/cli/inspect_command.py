"""Command ``agvdyn inspect``: the pre-flight check of identification logs."""
from __future__ import annotations

import json
from pathlib import Path
import typer
from rich.console import Console
from rich.table import Table

from agvdyn.cli._app import app, fail
from agvdyn.cli.identify_commands import FixOpt, MappingOpt, PlatformOpt, _fixed
from agvdyn.cli._defaults import MODE_TOLERANCE, STOP_TOLERANCE


def _print_file(console: Console, check, geom, max_rows: int) -> None:
    summary = check.summary
    console.print(f"[bold]{summary.path or '<log>'}[/bold]")
    console.print(f"samples   {summary.n_samples:,}")
    console.print(f"time      {summary.t_start:.6g} s .. {summary.t_end:.6g} s (duration {summary.duration:.3f} s)")
    console.print(f"rate      {summary.rate:.6g} Hz (median sample time {summary.sample_time * 1e3:.4g} ms)")
    console.print(f"platform  {geom.name} (l={geom.l:g} m, b={geom.b:g} m, i_G={geom.i_G:g})")
    for note in summary.notes:
        console.print(f"note      {note}")
    for gap in check.gaps:
        console.print(f"gap       {gap}")
    if summary.segments:
        table = Table(title="segments (labels)", title_justify="left")
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
        console.print(f"... {len(summary.modes) - max_rows:,} more runs (--max-rows, or --json for all)")
    totals = ", ".join(f"{k}: {v:.3f} s" for k, v in sorted(summary.mode_time.items()))
    console.print(f"time per mode (rows x sample time)  {totals}")
    timeline = " | ".join(f"{m} {a:.1f}-{b:.1f} s" for m, a, b in check.timeline[:max_rows])
    console.print(f"modes the identification uses (configuration and velocities)  {timeline}")
    c = check.rows.counts
    console.print(f"rows      {c.used:,} of {c.samples:,} used; edges {c.edge:,}, slip {c.slip:,}, no mode {c.no_mode:,}, "
                  f"too short {c.too_short:,}; clipped at the stops {sum(c.clipped_stop.values()):,}")
    if c.label_mismatch:
        console.print("labels    off the detected mode: " + ", ".join(f"{k} {v:,} rows" for k, v in c.label_mismatch.items()))
    for e in check.rows.slip_events:
        console.print(f"slip      t = {e.t_start:.3f}..{e.t_end:.3f} s, peak {e.peak_mps:.3g} m/s, wheels {', '.join(e.wheels)}")


@app.command()
def inspect(
    logs: list[Path] = typer.Argument(..., metavar="LOG...", help="Logs, tables or ROS 2 bags (with --mapping)."),
    mapping: MappingOpt = None,
    platform: PlatformOpt = None,
    fix: FixOpt = None,
    tolerance: float = typer.Option(MODE_TOLERANCE, help="Tolerance of the mode detection (rad), eq. (9)."),
    stop_tolerance: float = typer.Option(STOP_TOLERANCE, help="Steering angles this far beyond +-pi/2 (rad) are "
                                                               "clipped to the stop and counted; farther is an error."),
    min_duration: float = typer.Option(0.05, help="Mode runs shorter than this (s) are merged into the preceding "
                                                  "run in the list (0: list every run)."),
    max_rows: int = typer.Option(40, help="Longest list of mode runs printed; the rest is counted."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON (keys: docs/cli.md)."),
    strict: bool = typer.Option(False, "--strict", help="Exit with code 1 when the verdict is not ready."),
) -> None:
    """Pre-flight check: per file duration, rate, gaps, modes next to labels, clipped stops, slip; how
    well each parameter is excited and which experiment is missing; a verdict.

    Exit codes: 0 ok (with --strict: ready), 1 with --strict: not ready (a parameter not or weakly excited), 2 bad input.
    """
    from agvdyn.identification import IdentificationSettings, load_logs, platform_for
    from agvdyn.preflight import preflight

    fixed = _fixed(fix)
    try:
        settings = IdentificationSettings(mode_tolerance=tolerance)
        loaded = load_logs(logs, mapping=mapping, platform=platform, stop_tolerance=stop_tolerance)
        geom = platform_for(loaded, platform)
        result = preflight(loaded, geom, fixed=fixed, settings=settings, min_duration=min_duration)
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc
    if as_json:
        typer.echo(json.dumps(result.to_dict(), indent=2))
    else:
        console = Console(highlight=False)
        for check in result.files:
            _print_file(console, check, geom, max_rows)
            console.print()
        table = Table(title="excitation of the parameters by the rows kept", title_justify="left")
        for col in ("parameter", "status", "variance inflation", "relative std", "excited by"):
            table.add_column(col, justify="right" if col in ("variance inflation", "relative std") else "left")
        for e in result.excitation:
            table.add_row(e.name, e.status, "-" if e.inflation != e.inflation else f"{e.inflation:.3g}",
                          "-" if e.relative_std != e.relative_std else f"{100 * e.relative_std:.2g} %", e.excited_by)
        console.print(table)
        for w in result.warnings:
            console.print(f"[yellow]warning:[/yellow] {w}")
        console.print(f"[bold]verdict: {result.verdict}[/bold]")
    if strict and not result.ready:
        raise typer.Exit(1)
