"""Commands ``agvdyn identify``, ``agvdyn validate`` and ``agvdyn report`` (paper sec. 6.2-7)."""
from __future__ import annotations

import inspect
import json
import math
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console

from agvdyn.cli._app import app, fail, numbers_by_name
from agvdyn.cli._outputs import log_inputs, refuse_overwrite
from agvdyn.cli._tables import Column, print_items, print_parameters, print_table
from agvdyn.cli import _defaults as D, _model_options as M

# The library (scipy, numba) is imported inside the functions that use it: ``agvdyn --help`` stays fast.

_FIX_HELP = ("Parameter taken as known, NAME=VALUE (repeatable); default B_w=0.121. '--fix none' estimates all "
             "eleven: B_w is then told from m_ch and C_ch only by car-like motion with strong wheel accelerations, "
             "and refused as collinear, naming the three, when the logs lack it.")


# Options shared by identify, validate and report: one declaration each, so the commands agree.
PlatformOpt = Annotated[Optional[Path], typer.Option(
    help="Platform file (YAML); default: the platform in the log's sidecar, else the built-in prototype.")]
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
SteeringGuardOpt = Annotated[float, typer.Option(
    help="The same for the steering coordinates, whose reversals stick (default 4: 100 ms; 2, the chassis', "
         "biased C_l and C_r where the friction is large against the inertia; docs/identification.md).")]
OffsetsOpt = Annotated[bool, typer.Option("--offsets/--no-offsets",
                                          help="Estimate constant motor-torque offsets with the parameters.")]
SegmentsOpt = Annotated[Optional[str], typer.Option(
    help="Comma-separated segment labels whose rows are used; default: every row in a motion mode "
         "(labels are hints: each row's mode comes from its configuration).")]
SlipThresholdOpt = Annotated[Optional[float], typer.Option(
    help="Wheel slip speed (m/s) above which rows are dropped as slip; default: from the robust spread of "
         "the log's rolling-constraint residual; inf: no slip detection.")]
MaxInflationOpt = Annotated[float, typer.Option(
    help="Refuse parameters whose variance inflation factor exceeds this (inf: no check).")]
MaxRelativeStdOpt = Annotated[float, typer.Option(
    help="Refuse parameters whose std exceeds this fraction of the value (inf: no check).")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the result as JSON (keys: docs/cli.md).")]
EstimatorOpt = Annotated[str, typer.Option(
    help="ols (the paper's eq. 25), wls (weights per generalized coordinate), robust (IRLS, outliers such as "
         "slip down-weighted), bounded (masses, inertias > 0, frictions >= 0).")]
UncertaintyOpt = Annotated[str, typer.Option(
    help="classic (eq. 25, iid rows), hac (Newey-West for correlated residuals), jackknife (delete-one-block, "
         "the calibrated default) or bootstrap (moving blocks).")]
UnexcitedOpt = Annotated[Optional[str], typer.Option(
    help="refuse: parameters the data do not excite stop the identification, named; report: they get an "
         "unbounded 95 % interval (std null) and a warning, the rest is identified. Default: report with "
         "--estimator bounded, refuse otherwise.")]
TorqueLeadOpt = Annotated[Optional[float], typer.Option(
    help="Samples (0..1) by which each row's torque leads its angles: 0.5 for a drive that holds the logged "
         "torque until the next sample (zero-order hold). Default: the sidecar's torque_lead (the simulator "
         "writes 0.5), else 0.")]
BandwidthOpt = Annotated[Optional[int], typer.Option(
    help="HAC bandwidth / bootstrap block / half the jackknife block in samples; default: twice the residuals' "
         "correlation time, at least 50.")]


def _fixed(items: Optional[list[str]]) -> dict[str, float]:
    from agvdyn.identification import DEFAULT_FIXED
    from agvdyn.platform import PARAMETER_NAMES

    if not items:
        return dict(DEFAULT_FIXED)
    if [i.strip().lower() for i in items] == ["none"]:
        return {}
    return numbers_by_name("--fix", items, PARAMETER_NAMES)


def _settings(*, filtering: str = D.FILTERING, cutoff: float = D.CUTOFF, order: int = D.ORDER,
              stiction: float = D.STICTION, steering_stiction: float = D.STEERING_STICTION,
              stiction_guard: float = D.STICTION_GUARD, steering_guard: float = D.STEERING_GUARD,
              segments: Optional[str] = None, slip_threshold: Optional[float] = None,
              torque_lead: Optional[float] = None, offsets: bool = D.OFFSETS, max_inflation: float = D.MAX_INFLATION,
              max_relative_std: float = D.MAX_RELATIVE_STD, estimator: str = D.ESTIMATOR,
              unexcited: Optional[str] = None, uncertainty: str = D.UNCERTAINTY,
              bandwidth: Optional[int] = None) -> "IdentificationSettings":  # noqa: F821
    """The identification settings of the options (``_defaults.OPTION_FIELDS`` names the field each sets)."""
    from agvdyn.identification import Filtering, FitSettings, IdentificationSettings, RowSettings, UncertaintySettings
    from agvdyn.signals import FilterSettings

    try:
        mode = Filtering(filtering)
    except ValueError:
        raise fail(f"--filtering {filtering!r}: expected one of {[f.value for f in Filtering]}") from None
    try:
        rows = RowSettings(
            filter=FilterSettings(cutoff=cutoff, order=order), filtering=mode, stiction_threshold=stiction,
            steering_threshold=steering_stiction, stiction_guard=stiction_guard, steering_guard=steering_guard,
            slip_threshold=slip_threshold, torque_lead=torque_lead,
            segments=None if segments is None else tuple(s.strip() for s in segments.split(",") if s.strip()))
        fit = FitSettings(torque_offsets=offsets, max_inflation=max_inflation, max_relative_std=max_relative_std,
                          estimator=estimator, unexcited=unexcited)
        return IdentificationSettings(rows=rows, fit=fit,
                                      uncertainty=UncertaintySettings(method=uncertainty, bandwidth=bandwidth))
    except ValueError as exc:
        raise fail(str(exc)) from exc


def settings_of(options: dict) -> "IdentificationSettings":  # noqa: F821
    """The identification settings of a command's options (its ``locals()``): those of them that
    :func:`_settings` takes, the others left at their defaults."""
    return _settings(**{k: v for k, v in options.items() if k in _SETTING_OPTIONS})


_SETTING_OPTIONS = frozenset(inspect.signature(_settings).parameters)


def _identified(paths: list[Path], platform: Optional[Path], mapping: Optional[Path], fixed, settings,
                experiment: str = "auto", search=None, **options):
    """The logs opened (read one at a time, a long one in pieces: memory does not grow with their number
    or length), then identify() or, for lifted-wheel logs, identify_lifted() (``search``: the model's
    search or comparison instead, ``_model_options.modelled``); refusals for data quality as exit code 1,
    bad input as exit code 2."""
    from agvdyn.identification import (
        ImplausibleError, UnidentifiableError, experiment_of, identify as identify_parameters, identify_lifted,
        platform_for)
    from agvdyn.io import open_logs

    try:
        logs = open_logs(paths, mapping=mapping, platform=platform)
        geometry = platform_for(logs, platform)
        if experiment_of(logs, experiment) == "lifted-wheel":
            if search is not None:
                raise ValueError("--model, --compare-models: lifted-wheel logs are identified with the paper's model")
            return identify_lifted([log.load() for log in logs], geometry, settings=settings)
        kind = "auto" if str(experiment).strip().lower() == "auto" else "vehicle"
        if search is not None:
            return search(logs, geometry, fixed, settings, kind, options["workers"], options.get("check_rows", False))
        return identify_parameters(logs, geometry, fixed=fixed, settings=settings, experiment=kind, **options)
    except (UnidentifiableError, ImplausibleError) as exc:
        raise fail(f"refused: {exc}", code=1) from exc
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc


def _load(paths: list[Path], mapping: Optional[Path], platform: Optional[Path]):
    from agvdyn.identification import load_logs, platform_for

    try:
        logs = load_logs(paths, mapping=mapping, platform=platform)
        return logs, platform_for(logs, platform)
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc


@app.command()
def identify(
    logs: list[Path] = typer.Argument(..., metavar="LOG...", help="Identification logs (Parquet/CSV in our schema, or with --mapping)."),
    out: Path = typer.Option(..., "--out", "-o", help="Parameter file to write (.yaml, or .json)."),
    platform: PlatformOpt = None,
    fix: FixOpt = None,
    mapping: MappingOpt = None,
    filtering: FilteringOpt = D.FILTERING,
    cutoff: CutoffOpt = D.CUTOFF,
    order: OrderOpt = D.ORDER,
    stiction: StictionOpt = D.STICTION,
    steering_stiction: SteeringStictionOpt = D.STEERING_STICTION,
    stiction_guard: GuardOpt = D.STICTION_GUARD,
    steering_guard: SteeringGuardOpt = D.STEERING_GUARD,
    offsets: OffsetsOpt = D.OFFSETS,
    segments: SegmentsOpt = None,
    max_inflation: MaxInflationOpt = D.MAX_INFLATION,
    max_relative_std: MaxRelativeStdOpt = D.MAX_RELATIVE_STD,
    slip_threshold: SlipThresholdOpt = None,
    estimator: EstimatorOpt = D.ESTIMATOR,
    uncertainty: UncertaintyOpt = D.UNCERTAINTY,
    bandwidth: BandwidthOpt = None,
    unexcited: UnexcitedOpt = None,
    torque_lead: TorqueLeadOpt = None,
    experiment: Annotated[str, typer.Option(
        "--experiment", help="auto (from the segment labels), vehicle, or lifted-wheel: the single-axis test "
                             "of sec. 7 (wheels off the ground) gives B_w and the wheel friction without load.")] = "auto",
    threads: Annotated[Optional[int], typer.Option(
        "--threads", min=1, help="Threads reading and reducing the logs (default: the cores, at most 2; "
                                 "or AGVDYN_THREADS). The result does not depend on it.")] = None,
    model: M.ModelOpt = "paper",
    compare_models: M.CompareOpt = False,
    delay_range: M.DelayRangeOpt = None,
    stribeck_range: M.StribeckRangeOpt = None,
    validation: M.ValidationOpt = None,
    row_check: Annotated[bool, typer.Option(
        "--row-check/--no-row-check", help="Also fit the steering parameters on the stick-slip rows (filtering "
                                           "matched, steering guard 12) and warn when they move beyond their "
                                           "stds: breakaway friction biases the default rows (one more fit, "
                                           "of the model fitted; with the default rows only).")] = True,
    as_json: JsonOpt = False,
) -> None:
    """Identify the dynamic parameters from logs (eq. 22-25) and write the parameter file.

    Exit codes: 0 identified, 1 refused for data quality (not excited, implausible), 2 bad input.
    """
    refuse_overwrite({"--out": out}, {**log_inputs("LOG", logs), "--platform": platform, "--mapping": mapping,
                                      **log_inputs("--validation", [validation])}, kinds={"--out": "parameter file"})
    fixed = _fixed(fix)
    settings = settings_of(locals())
    search = M.search_of(model, compare_models, delay_range, stribeck_range, validation, mapping, platform, settings)
    ident = _identified(logs, platform, mapping, fixed, settings, experiment, search, keep_blocks=False, workers=threads,
                        check_rows=row_check)
    ident, selection = ident if isinstance(ident, tuple) else (ident, None)
    try:
        written = ident.write(out)
    except OSError as exc:
        raise fail(f"{out}: cannot be written: {exc}") from exc
    if as_json:
        data = M.with_selection(ident.to_json_dict(), selection)
        data["out"] = str(written)
        typer.echo(json.dumps(data, indent=2))
        return
    console = Console()
    if getattr(ident, "experiment", None) == "lifted_wheel":  # agvdyn.identification.lifted
        for name, entry in ident.to_json_dict()["parameters"].items():
            console.print(f"{name} = {entry['value']:.6g} +- {entry['std']:.2g} {entry['unit']}"
                          + (" (without load)" if name != "B_w" else ""))
        console.print(f"lifted wheels, cond {ident.condition_number:.4g}, rows per wheel {ident.rows}; use "
                      f"--fix B_w={ident.B_w:.6g} on the vehicle's logs")
        console.print(f"wrote {written}")
        return
    print_parameters(console, ident)
    print_items(console, "residual RMS per generalized torque:",
                [f"{k} {v:.4g}" for k, v in ident.residual_rms.items()])
    if ident.offsets:
        print_items(console, "motor-torque offsets (N m, motor side):",
                    [f"{k} {v:+.4f} +- {ident.offsets_std[k]:.2g}" for k, v in ident.offsets.items()])
    print_items(console, "rows:", _rows_items(ident), sep="; ")
    for event in ident.slip_events:
        console.print(f"wheel slip: {event.source} t = {event.t_start:.3f}..{event.t_end:.3f} s, peak "
                      f"{event.peak_mps:.3g} m/s, wheels {', '.join(event.wheels)} ({event.rows} rows)")
    for note in ident.notes:
        console.print(f"note: {note}")
    for warning in ident.warnings:
        console.print(f"[yellow]warning:[/yellow] {warning}")
    M.print_model(console, ident, selection)
    console.print(f"wrote {written}")


def _rows_items(ident) -> list[str]:
    r = ident.rows
    parts = [f"{r.used:,} of {r.samples:,} samples used"]
    parts += [f"{n:,} {what}" for n, what in (
        (r.edge, "at the filter edges"), (r.slip, "wheel slip"), (r.no_mode, "in no motion mode"),
        (r.not_selected, "in unselected segments"), (r.too_short, "in too short stretches")) if n]
    if sum(r.clipped_stop.values()):
        parts.append(f"{sum(r.clipped_stop.values()):,} clipped to the steering stops")
    if r.label_mismatch:
        parts.append("labels off the detected mode: " + ", ".join(f"{k} {v:,}" for k, v in r.label_mismatch.items()))
    return parts


def _nan_safe(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.4g}"


@app.command()
def validate(
    log: Path = typer.Argument(..., metavar="LOG", help="Validation log not used for identification (e.g. the lane change)."),
    params: Path = typer.Option(..., "--params", help="Parameter file (YAML/JSON) to validate."),
    platform: Annotated[Optional[Path], typer.Option(
        help="Platform file (YAML); default: the platform stored in the parameter file, else the platform in "
             "the log's sidecar, else the built-in prototype.")] = None,
    mapping: MappingOpt = None,
    filtering: FilteringOpt = D.FILTERING,
    cutoff: CutoffOpt = D.CUTOFF,
    order: OrderOpt = D.ORDER,
    stiction: StictionOpt = D.STICTION,
    steering_stiction: SteeringStictionOpt = D.STEERING_STICTION,
    stiction_guard: GuardOpt = D.STICTION_GUARD,
    steering_guard: SteeringGuardOpt = D.STEERING_GUARD,
    as_json: JsonOpt = False,
) -> None:
    """Predict the generalized torques of an unseen log and print the NRMSE per generalized coordinate."""
    from agvdyn.cli.model_commands import model_parameters_option
    from agvdyn.platform import PROTOTYPE, platform_of_parameters, read_parameters, read_platform
    from agvdyn.validation import validate as validate_log

    settings = settings_of(locals())
    try:
        content = read_parameters(params)
        override = None if platform is None else read_platform(platform)
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc
    (loaded,), log_geometry = _load([log], mapping, platform)
    geometry = log_geometry
    if content.geometry is not None or override is not None:
        geometry, warning = platform_of_parameters(content, override)
        if warning:
            typer.secho(f"warning: {warning}", fg=typer.colors.YELLOW, err=True)
        elif override is None and not geometry.same_shape(log_geometry) and log_geometry is not PROTOTYPE:
            typer.secho(f"warning: the log's sidecar names another platform ({log_geometry.describe()}) than the "
                        f"parameter file ({geometry.describe()}); using the parameter file's", fg=typer.colors.YELLOW,
                        err=True)
    try:
        val = validate_log(loaded, model_parameters_option(params, content.parameters), geometry, settings=settings)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    if as_json:
        typer.echo(json.dumps(val.to_json_dict(), indent=2))
        return
    columns = [Column("coordinate", "left"), Column("NRMSE"), Column("NRMSE w/o stiction rows"),
               Column("rows", drop=2), Column("rows moving", drop=1)]
    rows = [[str(row["coordinate"]), _nan_safe(row["nrmse"]), _nan_safe(row["nrmse_moving"]), f"{int(row['n_rows']):,}",
             f"{int(row['n_moving']):,}"] for row in val.rows]  # val.rows, not val.table: no pandas
    console = Console(highlight=False)
    print_items(console, f"Validation on {log}:", ["NRMSE = RMS(measured - model) / RMS(measured)"])
    print_table(console, "", columns, rows)
