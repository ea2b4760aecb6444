"""Command ``agvdyn batch``: identify a fleet from a YAML manifest on Dask, one Parquet table."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.text import Text

from agvdyn.cli._app import app, fail
from agvdyn.cli._tables import Column, print_table
from agvdyn.cli._outputs import log_inputs, refuse_overwrite


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
    inputs = {"MANIFEST": manifest}
    for job in jobs:
        inputs.update({**log_inputs(f"job {job.name}: LOG", job.logs), f"job {job.name}: platform": job.platform,
                       f"job {job.name}: mapping": job.mapping})
    refuse_overwrite({"--out": out}, inputs, {"--out": "table"})
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
        view = Console(highlight=False)
        columns = [Column("job", "left"), Column("status", "left"), Column("rows"), Column("cond"), Column("seconds")]
        print_table(view, f"{len(per_job)} jobs of {manifest}", columns, [
            [escape(str(name)), "ok" if ok else "[red]failed[/red]", f"{int(row['rows']):,}" if ok else "",
             f"{row['cond']:.4g}" if ok else "", f"{row['seconds']:.2f}"]
            for name, row in per_job.iterrows() for ok in [row["error"] == ""]])
        for name, row in failed.iterrows():  # below the table: an error is prose, wrapped between words
            view.print(Text(f"{name}: {row['error'].splitlines()[0]}", style="red"))
    typer.echo(f"wrote {out} ({len(table):,} rows; {len(per_job) - len(failed)} of {len(per_job)} jobs identified)")
