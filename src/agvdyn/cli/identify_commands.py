"""Commands ``agvdyn identify``, ``agvdyn validate`` and ``agvdyn report`` (paper sec. 6.2-7)."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from rich.console import Console
from rich.table import Table

from agvdyn.cli._app import app, fail
from agvdyn.identification import (
    DEFAULT_FIXED,
    Filtering,
    IdentificationSettings,
    identify as identify_parameters,
    load_logs,
    platform_for,
)
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PARAMETER_UNITS, read_parameters
from agvdyn.signals import FilterSettings

_FIX_HELP = ("Parameter taken as known, NAME=VALUE (repeatable); default B_w=0.121. "
             "'--fix none' estimates all eleven (needs car-like motion in the logs).")


# Options shared by identify, validate and report: one declaration each, so the commands agree.
PlatformOpt = Annotated[Optional[Path], typer.Option(
    help="Platform file (YAML); default: the log sidecar's platform, else the prototype.")]
FixOpt = Annotated[Optional[list[str]], typer.Option("--fix", help=_FIX_HELP)]
MappingOpt = Annotated[Optional[Path], typer.Option(help="Mapping file for logs not in our schema (tables, ROS 2 bags).")]
FilteringOpt = Annotated[str, typer.Option(
    help="parallel (filter regressor columns and torques alike) or literal (the paper's wording).")]
CutoffOpt = Annotated[float, typer.Option(help="Cut-off of the zero-phase Butterworth low-pass, rad/s.")]
OrderOpt = Annotated[int, typer.Option(help="Order of the Butterworth prototype.")]
StictionOpt = Annotated[float, typer.Option(
    help="Rows of x_ch, y_ch, gamma_ch with |generalized velocity| below this are dropped (m/s, rad/s).")]
SteeringStictionOpt = Annotated[float, typer.Option(
    help="The same for the steering coordinates alpha_l, alpha_r, alpha_v (rad/s).")]
GuardOpt = Annotated[float, typer.Option(
    help="Also drop rows within STICTION_GUARD / cutoff seconds of a stiction row (0: off).")]
OffsetsOpt = Annotated[bool, typer.Option("--offsets/--no-offsets",
                                          help="Estimate constant motor-torque offsets with the parameters.")]
SegmentsOpt = Annotated[Optional[str], typer.Option(
    help="Comma-separated segment names to use; default: every segment with a mode.")]
MaxInflationOpt = Annotated[float, typer.Option(
    help="Refuse parameters whose variance inflation factor exceeds this (inf: no check).")]
MaxRelativeStdOpt = Annotated[float, typer.Option(
    help="Refuse parameters whose std exceeds this fraction of the value (inf: no check).")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the result as JSON.")]


def _fixed(items: Optional[list[str]]) -> dict[str, float]:
    if not items:
        return dict(DEFAULT_FIXED)
    if [i.strip().lower() for i in items] == ["none"]:
        return {}
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or name not in PARAMETER_NAMES:
            raise fail(f"--fix {item!r}: expected NAME=VALUE with NAME one of {', '.join(PARAMETER_NAMES)}")
        try:
            out[name] = float(value)
        except ValueError:
            raise fail(f"--fix {item!r}: {value!r} is not a number") from None
        if not math.isfinite(out[name]):
            raise fail(f"--fix {item!r}: expected a finite number")
    return out


def _settings(filtering: str, cutoff: float, order: int, stiction: float, segments: Optional[str],
              steering_stiction: float = 0.1, offsets: bool = True, guard: float = 2.0,
              max_inflation: float = 100.0, max_relative_std: float = 0.5) -> IdentificationSettings:
    try:
        return IdentificationSettings(
            filter=FilterSettings(cutoff=cutoff, order=order), filtering=Filtering(filtering),
            stiction_threshold=stiction, steering_threshold=steering_stiction, torque_offsets=offsets,
            stiction_guard=guard, max_inflation=max_inflation, max_relative_std=max_relative_std,
            segments=None if segments is None else tuple(s.strip() for s in segments.split(",") if s.strip()))
    except ValueError as exc:
        raise fail(f"{exc} (filtering must be one of {[f.value for f in Filtering]})") from exc


def _load(paths: list[Path], mapping: Optional[Path], platform: Optional[Path]):
    try:
        logs = load_logs(paths, mapping=mapping, platform=platform)
        return logs, platform_for(logs, platform)
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc


def _parameter_table(ident) -> Table:
    table = Table(title=f"Identified parameters (cond(Theta_1w^T Theta_1w) = {ident.condition_number:.4g}, "
                        f"{ident.n_rows} rows)")
    for col in ("parameter", "value", "std", "unit", "Table 2", "deviation"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    for name in PARAMETER_NAMES:
        value = getattr(ident.parameters, name)
        ref = getattr(PAPER_PARAMETERS, name)
        std = "fixed" if name in ident.fixed else f"{ident.std[name]:.4g}"
        table.add_row(name, f"{value:.6g}", std, PARAMETER_UNITS[name], f"{ref:.6g}", f"{100 * (value / ref - 1):+.2f} %")
    return table


@app.command()
def identify(
    logs: list[Path] = typer.Argument(..., metavar="LOG...", help="Identification logs (Parquet/CSV in our schema, or with --mapping)."),
    out: Path = typer.Option(..., "--out", "-o", help="Parameter file to write (.yaml, or .json)."),
    platform: PlatformOpt = None,
    fix: FixOpt = None,
    mapping: MappingOpt = None,
    filtering: FilteringOpt = "parallel",
    cutoff: CutoffOpt = 40.0,
    order: OrderOpt = 4,
    stiction: StictionOpt = 0.05,
    steering_stiction: SteeringStictionOpt = 0.1,
    stiction_guard: GuardOpt = 2.0,
    offsets: OffsetsOpt = True,
    segments: SegmentsOpt = None,
    max_inflation: MaxInflationOpt = 100.0,
    max_relative_std: MaxRelativeStdOpt = 0.5,
    as_json: JsonOpt = False,
) -> None:
    """Identify the dynamic parameters from logs (eq. 22-25) and write the parameter file."""
    fixed = _fixed(fix)
    settings = _settings(filtering, cutoff, order, stiction, segments, steering_stiction, offsets, stiction_guard,
                         max_inflation, max_relative_std)
    loaded, geometry = _load(logs, mapping, platform)
    try:
        ident = identify_parameters(loaded, geometry, fixed=fixed, settings=settings)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    try:
        written = ident.write(out)
    except OSError as exc:
        raise fail(f"{out}: cannot be written: {exc}") from exc
    if as_json:
        data = ident.to_json_dict()
        data["out"] = str(written)
        typer.echo(json.dumps(data, indent=2))
        return
    console = Console()
    console.print(_parameter_table(ident))
    console.print("residual RMS per generalized torque: " +
                  ", ".join(f"{k} {v:.4g}" for k, v in ident.residual_rms.items()))
    if ident.offsets:
        console.print("motor-torque offsets (N m, motor side): " +
                      ", ".join(f"{k} {v:+.4f} +- {ident.offsets_std[k]:.2g}" for k, v in ident.offsets.items()))
    for note in ident.notes:
        console.print(f"note: {note}")
    console.print(f"wrote {written}")


def _nan_safe(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.4g}"


@app.command()
def validate(
    log: Path = typer.Argument(..., metavar="LOG", help="Validation log not used for identification (e.g. the lane change)."),
    params: Path = typer.Option(..., "--params", help="Parameter file (YAML/JSON) to validate."),
    platform: PlatformOpt = None,
    mapping: MappingOpt = None,
    filtering: FilteringOpt = "parallel",
    cutoff: CutoffOpt = 40.0,
    order: OrderOpt = 4,
    stiction: StictionOpt = 0.05,
    steering_stiction: SteeringStictionOpt = 0.1,
    stiction_guard: GuardOpt = 2.0,
    as_json: JsonOpt = False,
) -> None:
    """Predict the generalized torques of an unseen log and print the NRMSE per generalized coordinate."""
    from agvdyn.validation import validate as validate_log

    settings = _settings(filtering, cutoff, order, stiction, None, steering_stiction, True, stiction_guard)
    (loaded,), geometry = _load([log], mapping, platform)
    try:
        parameters = read_parameters(params).parameters
        val = validate_log(loaded, parameters, geometry, settings=settings)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    if as_json:
        typer.echo(json.dumps(val.to_json_dict(), indent=2))
        return
    table = Table(title=f"Validation on {log}: NRMSE = RMS(measured - model) / RMS(measured)")
    for col in ("generalized coordinate", "NRMSE", "NRMSE without stiction rows", "rows", "rows moving"):
        table.add_column(col, justify="left" if col.startswith("gen") else "right")
    for key, row in val.table.iterrows():
        table.add_row(str(key), _nan_safe(row["nrmse"]), _nan_safe(row["nrmse_moving"]), str(int(row["n_rows"])),
                      str(int(row["n_moving"])))
    Console().print(table)


@app.command()
def report(
    ident_logs: list[Path] = typer.Option(..., "--ident", help="Identification log (repeatable)."),
    out: Path = typer.Option(..., "--out", "-o", help="HTML report to write."),
    validation: Optional[Path] = typer.Option(None, "--validation", help="Validation log (e.g. the lane change)."),
    params_out: Optional[Path] = typer.Option(None, "--params-out", help="Also write the parameter file here."),
    platform: PlatformOpt = None,
    fix: FixOpt = None,
    mapping: MappingOpt = None,
    filtering: FilteringOpt = "parallel",
    cutoff: CutoffOpt = 40.0,
    order: OrderOpt = 4,
    stiction: StictionOpt = 0.05,
    steering_stiction: SteeringStictionOpt = 0.1,
    stiction_guard: GuardOpt = 2.0,
    offsets: OffsetsOpt = True,
    segments: SegmentsOpt = None,
    max_inflation: MaxInflationOpt = 100.0,
    max_relative_std: MaxRelativeStdOpt = 0.5,
) -> None:
    """Identify, validate and write one self-contained HTML report (Table 2, Fig. 5, Fig. 6)."""
    from agvdyn.report import reference_parameters, write_report
    from agvdyn.validation import validate as validate_log

    fixed = _fixed(fix)
    settings = _settings(filtering, cutoff, order, stiction, segments, steering_stiction, offsets, stiction_guard,
                         max_inflation, max_relative_std)
    loaded, geometry = _load(ident_logs, mapping, platform)
    try:
        ident = identify_parameters(loaded, geometry, fixed=fixed, settings=settings)
        val = None
        if validation is not None:
            (val_log,), _ = _load([validation], mapping, platform)
            val = validate_log(val_log, ident.parameters, geometry, settings=settings)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    reference, reference_std, label = reference_parameters(loaded)
    inputs: dict[str, Any] = {"fixed": ", ".join(f"{k}={v}" for k, v in fixed.items()) or "none"}
    try:
        if params_out is not None:
            typer.echo(f"wrote {ident.write(params_out)}")
        written = write_report(out, ident, val, reference=reference, reference_std=reference_std,
                               reference_label=label, inputs=inputs)
    except OSError as exc:
        raise fail(f"cannot write the report: {exc}") from exc
    typer.echo(f"wrote {written}")
