"""Command ``agvdyn track``: replay logs through the online payload tracker (issue 31, docs/online.md)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from agvdyn.cli._app import app, fail, platform_option
from agvdyn.cli._outputs import log_inputs, refuse_overwrite


@app.command()
def track(
    logs: list[Path] = typer.Argument(..., metavar="LOG...", help="Logs to replay, in time order (one shift)."),
    params: Path = typer.Option(..., "--params", help="Identified parameters (YAML/JSON): all but m_ch and C_ch "
                                "are held; m_ch and C_ch (with their std) are the start."),
    out: Path = typer.Option(..., "--out", help="Table to write (.parquet or .csv): t, m_ch, m_ch_std, C_ch, "
                             "C_ch_std, [x_c, x_c_std, y_c, y_c_std,] nis, event."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the parameter file's, "
                                            "else the built-in prototype."),
    rate: float = typer.Option(10.0, "--rate", help="Rows of the table per second (decimated; events kept)."),
    threshold: float = typer.Option(8.0, "--threshold", help="CUSUM threshold of the change detection "
                                    "(larger: fewer false alarms, later detection)."),  # TrackerSettings.threshold
    com_offset: bool = typer.Option(False, "--com-offset", help="Track the centre-of-mass offset y_c as well "
                                    "(from car-like turns; x_c is not identifiable: NaN, infinite std). Implied "
                                    "by a parameter file whose model block has com_offset: true (its y_c is the "
                                    "start)."),
    as_json: bool = typer.Option(False, "--json", help="Print events and final estimates as JSON."),
    engine: str = typer.Option("python", "--engine", metavar="python|cpp", help="The tracker's update: python "
                               "(the reference, numba) or cpp (agvdyn_ff::PayloadTracker through agvdyn.ffcpp; "
                               "the same numbers); the causal rows are Python's either way."),
) -> None:
    """Track m_ch and C_ch (and y_c with --com-offset) through logs and detect payload changes (recursive
    estimate, CUSUM, reset)."""
    if out.suffix.lower() not in (".parquet", ".csv"):
        raise fail(f"--out {out}: unknown suffix {out.suffix!r}: expected .parquet or .csv")
    if not rate > 0:
        raise fail(f"--rate {rate}: expected > 0 Hz")
    if engine not in ("python", "cpp"):
        raise fail(f"--engine {engine}: expected python or cpp")
    refuse_overwrite({"--out": out}, {**log_inputs("LOG", logs), "--params": params, "--platform": platform},
                     {"--out": "table"})
    from agvdyn._files import write_atomically
    from agvdyn.cli.model_commands import model_parameters_option
    from agvdyn.cli.sim_commands import _parameter_file
    from agvdyn.io import load_logs
    from agvdyn.online import TrackerSettings

    if engine == "cpp":
        from agvdyn import ffcpp
        from agvdyn.online.cpp import track as run

        try:
            ffcpp.extension()  # before the logs are read
        except ffcpp.CppEngineUnavailable as exc:
            raise fail(str(exc)) from exc
    else:
        from agvdyn.online import track as run
    from agvdyn.platform import platform_of_parameters

    content = _parameter_file(params)
    model = model_parameters_option(params, content.parameters)  # the paper's parameters, or a model beyond them
    held = model if getattr(getattr(model, "spec", None), "com_offset", False) else content.parameters
    geom, warning = platform_of_parameters(content, None if platform is None else platform_option(platform))
    if warning is not None:
        typer.secho(f"warning: {warning}", fg=typer.colors.YELLOW, err=True)
    try:
        loaded = load_logs(logs)
        result = run(loaded, geom, held, std=content.std,
                     settings=TrackerSettings(threshold=threshold, com_offset=com_offset))
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc
    import pandas as pd

    table = pd.DataFrame(result.table(rate))
    if out.suffix.lower() == ".csv":
        write_atomically(out, lambda tmp: table.to_csv(tmp, index=False))
    else:
        write_atomically(out, lambda tmp: table.to_parquet(tmp, index=False))
    if as_json:
        typer.echo(json.dumps({**result.to_dict(), "out": str(out), "rows": len(table)}, indent=2))
        return
    for e in result.events:
        typer.echo(f"{e.parameter} changed at ~{e.t_change_estimate:.2f} s (detected {e.t_detected:.2f} s): "
                   f"{e.before:.1f} +- {e.before_std:.1f} -> {e.after:.1f} +- {e.after_std:.1f}")
    final = result.final()
    offset = (f", y_c {100 * final['y_c']['value']:.2f} +- {100 * final['y_c']['std']:.2f} cm (x_c not identifiable)"
              if "y_c" in final else "")
    typer.echo(f"final m_ch {final['m_ch']['value']:.1f} +- {final['m_ch']['std']:.1f} kg, "
               f"C_ch {final['C_ch']['value']:.2f} +- {final['C_ch']['std']:.2f} kg m^2{offset}; "
               f"wrote {out} ({len(table):,} rows)")
