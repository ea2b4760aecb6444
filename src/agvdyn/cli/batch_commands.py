"""Command ``agvdyn batch``: identify a fleet from a YAML manifest on Dask, one Parquet table."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from agvdyn.cli._app import app, fail


@app.command()
def batch(
    manifest: Path = typer.Argument(..., help="Manifest (YAML): jobs: [{name, logs: [...], platform, fix: {B_w: ..}, "
                                    "mapping, estimator, uncertainty, settings, tags}, ...]; relative paths from "
                                    "the manifest's folder (docs/cli.md)."),
    out: Path = typer.Option(..., "--out", "-o", help="Table to write (.parquet): one row per job and parameter; "
                             "job, parameter, value, std, ci_low, ci_high, cond, rows, seconds, error, ..."),
    workers: int = typer.Option(2, "--workers", help="Processes of the local Dask cluster (one thread each); "
                                "ignored with --scheduler."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of a running Dask scheduler "
                                            "(tcp://host:port) whose workers run the jobs; default: a local cluster."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON (keys: docs/cli.md)."),
    quiet: bool = typer.Option(False, "--quiet", help="No progress bar and no table."),
) -> None:
    """Identify every job of a manifest (one vehicle each) in parallel on Dask and write one Parquet table.

    A failed job (missing log, unexcited data, ...) is a row with its error; the others complete.
    Exit codes: 0 the batch ran (failed jobs are in the table), 2 bad manifest or options.
    """
    from agvdyn._files import write_atomically
    from agvdyn.batch import ManifestError, read_manifest, run_batch

    if out.suffix.lower() != ".parquet":
        raise fail(f"--out {out}: expected a .parquet file")
    if workers < 1:
        raise fail(f"--workers {workers}: expected at least 1")
    try:
        jobs = read_manifest(manifest)
    except ManifestError as exc:
        raise fail(str(exc)) from exc
    console = Console(stderr=True)
    try:
        if quiet or as_json:
            table = run_batch(jobs, workers=workers, scheduler=scheduler)
        else:
            with Progress(TextColumn("batch"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                          console=console) as bar:
                task = bar.add_task("jobs", total=len(jobs))
                table = run_batch(jobs, workers=workers, scheduler=scheduler,
                                  progress=lambda done, total: bar.update(task, completed=done))
    except (OSError, TimeoutError, ValueError) as exc:  # no scheduler at the address, a bad address
        raise fail(f"cannot run the batch{' on ' + scheduler if scheduler else ''}: {exc}") from exc
    try:
        write_atomically(out, lambda tmp: table.to_parquet(tmp, index=False))
    except OSError as exc:
        raise fail(f"{out}: cannot be written: {exc}") from exc
    per_job = table.groupby("job", sort=False).agg(error=("error", "first"), rows=("rows", "first"),
                                                    cond=("cond", "first"), seconds=("seconds", "first"))
    failed = per_job[per_job["error"] != ""]
    if as_json:
        typer.echo(json.dumps({"out": str(out), "jobs": len(per_job), "failed": len(failed),
                               "errors": {str(k): v for k, v in failed["error"].items()}}, indent=2))
        return
    if not quiet:
        view = Table(title=f"{len(per_job)} jobs of {manifest}")
        for col in ("job", "status", "rows", "cond", "seconds"):
            view.add_column(col, justify="left" if col in ("job", "status") else "right")
        for name, row in per_job.iterrows():
            ok = row["error"] == ""
            view.add_row(str(name), "ok" if ok else f"[red]{row['error'].splitlines()[0]}[/red]", f"{int(row['rows']):,}" if ok else "",
                         f"{row['cond']:.4g}" if ok else "", f"{row['seconds']:.2f}")
        Console(highlight=False).print(view)
    typer.echo(f"wrote {out} ({len(table):,} rows; {len(per_job) - len(failed)} of {len(per_job)} jobs identified)")
