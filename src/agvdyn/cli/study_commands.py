"""Command ``agvdyn montecarlo``: estimators against the simulated truth over many noise seeds."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from agvdyn._files import write_atomically
from agvdyn.cli._app import app, fail, platform_option
from agvdyn.cli._defaults import ESTIMATORS
from agvdyn.cli._outputs import refuse_overwrite, trajectory_input


@app.command()
def montecarlo(
    out: Path = typer.Option(..., "--out", "-o", help="Study table to write (.parquet): run, estimator, "
                             "uncertainty, parameter, value, std, ci_low, ci_high, truth, seconds, ..."),
    runs: int = typer.Option(30, "--runs", help="Number of simulated runs (noise seeds)."),
    estimator: Optional[list[str]] = typer.Option(None, "--estimator", help=f"Estimator (repeatable): "
                                                  f"{', '.join(ESTIMATORS)}; default: the identification default."),
    uncertainty: Optional[list[str]] = typer.Option(None, "--uncertainty", help="Uncertainty method (repeatable): "
                                                    "classic, hac, jackknife, bootstrap; default: the identification default."),
    experiment: str = typer.Option("identification", help="Experiment simulated each run: identification, "
                                   "lane-change, lateral, or a trajectory file."),
    settings: Optional[Path] = typer.Option(None, help="Simulation settings (YAML, see docs/simulation.md)."),
    ideal_plant: bool = typer.Option(False, "--ideal-plant", help="Plant = model: neglected effects off and "
                                     "rigid tyres, so the truth is exact."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the built-in prototype."),
    seed: int = typer.Option(1000, help="Seed of the first run; run i uses seed + i."),
    workers: int = typer.Option(2, help="Processes running the runs in parallel."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of a running Dask scheduler "
                                            "(tcp://host:port) whose workers run the runs; default: --workers "
                                            "local processes."),
) -> None:
    """Repeat simulate -> identify with different noise seeds; print bias, RMSE, mean reported std,
    RMSE / mean std, 95 % coverage and time per estimator and parameter."""
    import yaml

    from agvdyn.identification import IdentificationSettings
    from agvdyn.identification.uncertainty import UncertaintyMethod
    from agvdyn.montecarlo import StudyCase, run_study, summarize

    refuse_overwrite({"--out": out}, {**trajectory_input(experiment, "--experiment"), "--settings": settings,
                                      "--platform": platform}, {"--out": "table"})
    if out.suffix.lower() != ".parquet":
        raise fail(f"--out {out}: expected a .parquet file")
    if runs < 2:
        raise fail(f"--runs {runs}: expected at least 2")
    defaults = IdentificationSettings()
    estimators = estimator or [defaults.fit.estimator.value]
    methods = uncertainty or [defaults.uncertainty.method.value]
    for e in estimators:
        if e not in ESTIMATORS:
            raise fail(f"--estimator {e!r}: expected one of {sorted(ESTIMATORS)}")
    for m in methods:
        if m not in [u.value for u in UncertaintyMethod]:
            raise fail(f"--uncertainty {m!r}: expected one of {[u.value for u in UncertaintyMethod]}")
    sim = {}
    if settings is not None:
        try:
            sim = yaml.safe_load(settings.read_text(encoding="utf-8")) or {}
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise fail(f"{settings}: cannot be read as YAML: {exc}") from exc
    geom = platform_option(platform)
    pairs = tuple((e, m) for e in estimators for m in methods)
    cases = [StudyCase(i, seed + i, experiment, sim, ideal_plant, pairs, geom.to_dict() if platform else None)
             for i in range(runs)]
    console = Console(stderr=True)
    try:
        with Progress(TextColumn("montecarlo"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      console=console) as bar:
            task = bar.add_task("runs", total=runs)
            table = run_study(cases, workers=workers, progress=lambda done, total: bar.update(task, completed=done),
                              scheduler=scheduler)
    except (ValueError, OSError, TimeoutError) as exc:
        raise fail(str(exc)) from exc
    write_atomically(out, lambda tmp: table.to_parquet(tmp, index=False))
    summary = summarize(table)
    view = Table(title=f"{runs} runs of {experiment}{' (ideal plant)' if ideal_plant else ''}: error and reported "
                       "uncertainty against the simulated truth")
    for col in ("estimator", "uncertainty", "parameter", "bias %", "RMSE %", "mean std %", "RMSE/std",
                "coverage 95 (Wilson 95 %)",
                "failed", "s/run"):
        view.add_column(col, justify="left" if col in ("estimator", "uncertainty", "parameter") else "right")
    for (est, unc, name), row in summary.iterrows():
        view.add_row(est, unc, name, f"{row.bias_pct:+.3f}", f"{row.rmse_pct:.3f}", f"{row.mean_std_pct:.3f}",
                     f"{row.rmse_over_std:.2f}",
                     f"{100 * row.coverage:.0f} % ({100 * row.coverage_low:.0f}-{100 * row.coverage_high:.0f})",
                     f"{int(row.failed)}",
                     f"{row.seconds:.2f}")
    console = Console()
    if not console.is_terminal:  # piped or logged: the whole table, not wrapped to 80 columns
        console = Console(width=132)
    console.print(view)
    typer.echo(f"wrote {out} ({len(table):,} rows)")
