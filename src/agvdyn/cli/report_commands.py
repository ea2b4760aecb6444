"""``agvdyn report``: identify, validate and judge in one self-contained HTML report."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from agvdyn.cli._app import app, fail
from agvdyn.cli._outputs import log_inputs, refuse_overwrite
from agvdyn.cli import _defaults as D
from agvdyn.cli.identify_commands import (
    BandwidthOpt, CutoffOpt, EstimatorOpt, FilteringOpt, FixOpt, GuardOpt, JsonOpt, MappingOpt, MaxInflationOpt,
    MaxRelativeStdOpt, OffsetsOpt, OrderOpt, PlatformOpt, SegmentsOpt, SlipThresholdOpt, SteeringGuardOpt,
    SteeringStictionOpt, StictionOpt, TorqueLeadOpt, UncertaintyOpt, UnexcitedOpt, _fixed, _load, settings_of,
)


@app.command()
def report(
    ident_logs: list[Path] = typer.Option(..., "--ident", help="Identification log (repeatable)."),
    out: Path = typer.Option(..., "--out", "-o", help="HTML report to write (one self-contained file)."),
    validation: Optional[Path] = typer.Option(None, "--validation", help="Validation log not used for "
                                              "identification (e.g. the lane change)."),
    reference: Optional[Path] = typer.Option(None, "--reference", help="Parameter file (YAML/JSON) to compare the "
                                             "estimates with; default: the simulator's true parameters of the log "
                                             "sidecar, else Table 2 of the paper when the platform is the built-in "
                                             "prototype, else no comparison."),
    params_out: Optional[Path] = typer.Option(None, "--params-out", help="Also write the parameter file here "
                                              "(.yaml, or .json)."),
    plan: Optional[Path] = typer.Option(None, "--plan", help="Plan file (agvdyn plan --out) the logs were driven "
                                        "from: the report shows its floor, the planned and driven paths, cond and "
                                        "predicted std; default: the plan a simulated log's sidecar names, found "
                                        "next to the log or in the working directory."),
    track: bool = typer.Option(False, "--track", help="Also track m_ch, C_ch over the logs (agvdyn track)."),
    tracking: Optional[Path] = typer.Option(None, "--tracking", help="Show this agvdyn track --out table."),
    compare_models: bool = typer.Option(False, "--compare-models", help="Compare the paper's model with its "
                                        "extensions (breakaway friction, torque delay, off-centre load; scored also "
                                        "on --validation) and report the one the data choose, as identify --model "
                                        "auto (slower: tens of fits)."),
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
    as_json: JsonOpt = False,
) -> None:
    """Identify, validate and write one self-contained HTML report: verdict, data quality, excitation plan
    (when there is one), parameters, correlation, residuals, Fig. 5, Fig. 6, tracking and provenance.

    Exit codes: 0 identified (with or without warnings), 1 refused (the report says why), 2 bad input.
    """
    from agvdyn.report import Outcome, command_line, make_report, read_plan, reference_from_file, write_report

    outputs = {"--out": out, "--params-out": params_out}
    kinds = {"--out": "HTML report", "--params-out": "parameter file"}
    refuse_overwrite(outputs, {**log_inputs("--ident", ident_logs), **log_inputs("--validation", [validation]),
                               "--reference": reference, "--plan": plan, "--platform": platform, "--mapping": mapping,
                               "--tracking": tracking},
                     kinds)
    fixed = _fixed(fix)
    settings = settings_of(locals())
    try:
        ref = None if reference is None else reference_from_file(reference)
    except (ValueError, OSError) as exc:
        raise fail(f"--reference {reference}: {exc}") from exc
    loaded, geometry = _load(ident_logs, mapping, platform)
    val_log = None if validation is None else _load([validation], mapping, platform)[0][0]
    try:
        plan_file = None if plan is None else read_plan(plan, geometry)
    except ValueError as exc:
        raise fail(f"--plan: {exc}") from exc
    extra = {role: path for role, path in (("mapping", mapping), ("platform", platform), ("reference", reference),
                                           ("tracking", tracking)) if path is not None}
    try:
        rep = make_report(loaded, geometry, fixed=fixed, settings=settings, validation_log=val_log, reference=ref,
                          extra_files=extra, command=command_line(), plan=plan_file, track=track, tracking=tracking,
                          models="compare" if compare_models else "paper")
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc
    if rep.plan is not None and rep.plan.found == "sidecar":  # found only now, by the logs' sidecars
        refuse_overwrite(outputs, {"plan file named by a log's sidecar": rep.plan.file.path}, kinds)
    try:
        written_params = None
        if params_out is not None and rep.identification is not None:
            written_params = rep.identification.write(params_out)
        written = write_report(out, rep)
    except OSError as exc:
        raise fail(f"cannot write the report: {exc}") from exc
    verdict = rep.verdict
    if as_json:
        data = rep.to_json_dict()
        data.update(out=str(written), params_out=None if written_params is None else str(written_params))
        typer.echo(json.dumps(data, indent=2))
    else:
        color = {Outcome.IDENTIFIED: typer.colors.GREEN, Outcome.WARNINGS: typer.colors.YELLOW,
                 Outcome.REFUSED: typer.colors.RED}[verdict.outcome]
        if verdict.outcome is Outcome.REFUSED:
            typer.secho(f"refused: {verdict.summary}", fg=color, bold=True)
        else:
            typer.secho(f"verdict: {verdict.outcome.value}", fg=color, bold=True)
            typer.echo(verdict.summary)
        for reason in verdict.reasons:
            typer.echo(f"  - {reason}")
        if written_params is not None:
            typer.echo(f"wrote {written_params}")
        typer.echo(f"wrote {written}")
    if verdict.outcome is Outcome.REFUSED:
        raise typer.Exit(1)
