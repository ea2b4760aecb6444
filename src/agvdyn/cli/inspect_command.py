"""Command ``agvdyn inspect``: the pre-flight check of identification logs."""
from __future__ import annotations

import json
from pathlib import Path
import typer
from rich.console import Console

from agvdyn.cli._app import app, fail
from agvdyn.cli._tables import Column, print_items, print_table
from agvdyn.cli.identify_commands import FixOpt, MappingOpt, PlatformOpt, _fixed
from agvdyn.cli._defaults import MODE_TOLERANCE, STOP_TOLERANCE


def _print_file(console: Console, check, geom, max_rows: int, min_run: float) -> None:
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
    times = [Column("start (s)"), Column("end (s)"), Column("duration (s)")]
    if summary.segments:
        print_table(console, "segments (labels)", [Column("name", "left"), *times],
                    [[s.name, f"{s.t_start:.3f}", f"{s.t_end:.3f}", f"{s.duration:.3f}"] for s in summary.segments])
    else:
        console.print("segments  none (no segment column)")
    detected, shown = check.mode_rows(0), check.mode_rows(min_run)
    merged = len(shown) < len(detected)
    print_table(console, f"motion modes detected from alpha (eq. 9, tolerance {summary.tolerance:g} rad)",
                [Column("mode", "left"), *times] + ([Column("merged", "left")] if merged else []),
                [[r.mode, f"{r.t_start:.3f}", f"{r.t_end:.3f}", f"{r.duration:.3f}"]
                 + ([f"{r.runs} runs" if r.runs > 1 else ""] if merged else []) for r in shown[:max_rows]])
    if len(shown) > max_rows:
        console.print(f"... {len(shown) - max_rows:,} more rows (--max-rows, or --json)")
    if merged:
        console.print(f"merged {len(detected) - len(shown):,} of {len(detected):,} detected runs into their "
                      f"neighbours (runs shorter than {min_run:g} s, --min-run; a merged row's mode is the one with "
                      "the most time in it)")
    print_items(console, "time per mode (rows x sample time):",
                [f"{k}: {v:.3f} s" for k, v in sorted(summary.mode_time.items())])
    timeline = check.timeline_rows(min_run)
    print_items(console, "modes the identification uses (configuration and velocities):",
                [f"{r.mode} {r.t_start:.1f}-{r.t_end:.1f} s" + (f" ({r.runs} runs)" if r.runs > 1 else "")
                 for r in timeline[:max_rows]] + ([f"... {len(timeline) - max_rows:,} more"]
                                                  if len(timeline) > max_rows else []), sep=" | ")
    c = check.rows.counts
    print_items(console, "rows     ", [f"{c.used:,} of {c.samples:,} used", f"edges {c.edge:,}", f"slip {c.slip:,}",
                                      f"no mode {c.no_mode:,}", f"too short {c.too_short:,}",
                                      f"clipped at the stops {sum(c.clipped_stop.values()):,}"], indent=10)
    if c.label_mismatch:
        print_items(console, "labels    off the detected mode:",
                    [f"{k} {v:,} rows" for k, v in c.label_mismatch.items()], indent=10)
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
                                                  "run in the --json lists modes and mode_timeline (0: every run)."),
    min_run: float = typer.Option(0.5, "--min-run", min=0.0, metavar="SECONDS", help=(
        "In the printed timelines, mode runs shorter than this (s) are merged into their neighbours, the row "
        "marked with the number of runs it holds (0: print every run). --json does not depend on it.")),
    max_rows: int = typer.Option(40, help="Longest list of mode runs printed; the rest is counted."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON (keys: docs/cli.md)."),
    strict: bool = typer.Option(False, "--strict", help="Exit with code 1 when the verdict is not ready."),
) -> None:
    """Pre-flight check: per file duration, rate, gaps, modes next to labels, clipped stops, slip; how
    well each parameter is excited and which experiment is missing; a verdict.

    Exit codes: 0 ok (with --strict: ready), 1 with --strict: not ready (a parameter not or weakly excited), 2 bad input.
    """
    from agvdyn.identification import IdentificationSettings, RowSettings, load_logs, platform_for
    from agvdyn.preflight import preflight

    fixed = _fixed(fix)
    try:
        settings = IdentificationSettings(rows=RowSettings(mode_tolerance=tolerance))
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
            _print_file(console, check, geom, max_rows, min_run)
            console.print()
        print_table(console, "excitation of the parameters by the rows kept",
                    [Column("parameter", "left"), Column("status", "left"), Column("variance inflation"),
                     Column("relative std")],
                    [[e.name, e.status, "-" if e.inflation != e.inflation else f"{e.inflation:.3g}",
                      "-" if e.relative_std != e.relative_std else f"{100 * e.relative_std:.2g} %"]
                     for e in result.excitation])
        excited_by: dict[str, list[str]] = {}
        for e in result.excitation:
            excited_by.setdefault(e.excited_by, []).append(e.name)
        for text, names in excited_by.items():
            if text:
                console.print(f"{', '.join(names)} excited by {text}")
        for w in result.warnings:
            console.print(f"[yellow]warning:[/yellow] {w}")
        console.print(f"[bold]verdict: {result.verdict}[/bold]")
    if strict and not result.ready:
        raise typer.Exit(1)
