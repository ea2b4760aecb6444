"""Command ``agvdyn plan``: the optimal identification sequence in a floor rectangle (sec. 6.2)."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from agvdyn.cli._app import app, fail, platform_option
from agvdyn.cli._outputs import refuse_overwrite

#: Default of ``--verify`` (docs/planning.md, "Stop 22").
VERIFY_DEFAULT = 4
#: The check simulates at most this many starts, best predicted objective first (~1.5 s each with four
#: seeds, the build included): half of the default search's twelve.
VERIFY_CANDIDATES = 6
#: Default of ``--verify-plants``: plant variants (``agvdyn.plan_check.PLANT_VARIANTS``) every candidate is
#: also simulated on (docs/planning.md, "Stop 22, second helper").
VERIFY_PLANTS: tuple[str, ...] = ()
#: Noise seeds per plant variant.
VERIFY_PLANT_SEEDS = 2
#: Default of ``--search`` (``agvdyn.trajectories.planner.SEARCHES``; docs/planning.md, "Stop 23").
SEARCH_DEFAULT = "wide"


@app.command()
def plan(
    out: Path = typer.Option(..., "--out", "-o", help="Trajectory file to write (.yaml, the segment format of "
                             "docs/simulation.md) for simulate and feedforward."),
    floor: str = typer.Option("5.2x1.6", help="Floor rectangle LENGTHxWIDTH in metres, the vehicle's footprint "
                              "included (length along the straight motion)."),
    duration: Optional[float] = typer.Option(None, help="Total duration in s, alignments included; default: the "
                                             "default sequence's (117.6 s on the prototype)."),
    objective: str = typer.Option("std", help="std (predicted relative std, default), d-optimal, or cond "
                                  "(condition number of the column-scaled regressor)."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the built-in prototype."),
    params: Optional[Path] = typer.Option(None, help="Nominal parameters (YAML/JSON) for the feed-forward torques "
                                          "and the relative stds; default: Table 2 with B_w = 0.121."),
    settings: Optional[Path] = typer.Option(None, help="Simulation settings (YAML) whose limits group (and the "
                                            "plant's torque_limit) bound the plan; see docs/simulation.md."),
    search: str = typer.Option(SEARCH_DEFAULT, help="Search of the optimiser: wide (the default: twelve "
                               "starts, a smooth bound on the peaks, 80 iterations each and the best four on to 300), "
                               "narrow (six starts of 300 iterations, each phase scaled to its largest peak), or both "
                               "(narrow,wide: the check chooses among the best six of each; the first's best start "
                               "unless another is measured better; with --verify 0 the first alone)."),
    starts: Optional[int] = typer.Option(None, help="Random starts of the optimiser (default: the search's, 12 or 6)."),
    seed: int = typer.Option(0, help="Seed of the starts."),
    verify: int = typer.Option(VERIFY_DEFAULT, "--verify", min=0, help="Noise seeds per candidate for a check on the "
                               "simulator: the best starts (at most six) and the default sequence are simulated and identified "
                               "(identify's defaults) on seeds 100, 101, ... and the candidate furthest inside the "
                               "bars (std ratios, cond, errors) is kept; 0: off (the best predicted objective)."),
    verify_plants: str = typer.Option(",".join(VERIFY_PLANTS) or "none", "--verify-plants",
                                      help="Plant variants the check also simulates every candidate and the default "
                                      "sequence on (two seeds each), comma-separated: soft, stiff (tyres), radii (wheel "
                                      "radii), breakaway (static friction 1.3x); a candidate's score pools all its runs; "
                                      "none: the nominal plant alone."),
    verify_engine: str = typer.Option("ours", "--verify-engine", help="Plant of the check: ours (the default) or "
                                      "mujoco (the MuJoCo plant generated from the platform and --params: the check on "
                                      "a second, independent engine; no --verify-plants with it)."),
    figure: Optional[Path] = typer.Option(None, help="Also save the floor, path and predicted stds as a figure "
                                          "(.png, .svg or .pdf)."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Plan the four-phase identification sequence (steer left, steer right, straight, rotation) for a floor
    and a duration, and compare it with the default sequence in the same floor."""
    from agvdyn._files import write_atomically, write_text_atomically
    from agvdyn.cli.sim_commands import _params
    from agvdyn.simulation import SimulationSettings, read_settings
    from agvdyn.trajectories import TrajectoryError
    from agvdyn.trajectories.planner import FREE, SEARCHES, PlanSettings, combine, parse_floor, plan as make_plan

    import yaml

    refuse_overwrite({"--out": out, "--figure": figure},
                     {"--platform": platform, "--params": params, "--settings": settings},
                     {"--out": "plan", "--figure": "figure"})
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise fail(f"--out {out}: unknown suffix {out.suffix!r}: expected .yaml or .yml")
    try:
        sim = SimulationSettings() if settings is None else read_settings(settings)
        searches = [name.strip() for name in search.split(",") if name.strip()]
        if not searches or len(set(searches)) < len(searches):
            raise ValueError(f"--search {search!r}: expected one or more different names of {', '.join(SEARCHES)}")
        if verify == 0:  # without the check only the first search's best start would be used
            searches = searches[:1]
        plan_settings = []
        for name in searches:
            one = PlanSettings.search(name, objective=objective, seed=seed)
            if starts is not None:
                one = replace(one, starts=starts)
            plan_settings.append(replace(one, candidates=min(one.starts, VERIFY_CANDIDATES) if verify > 0 else 1))
        rectangle = parse_floor(floor)
        plants = _plants(verify_plants)
        if verify_engine not in ("ours", "mujoco"):
            raise ValueError(f"--verify-engine {verify_engine!r}: expected ours or mujoco")
        if plants and verify_engine != "ours":
            raise ValueError(f"--verify-plants {verify_plants}: the plant variants are our plant's; expected none "
                             f"with --verify-engine {verify_engine}")
    except ValueError as exc:
        raise fail(str(exc)) from exc
    limits = sim.limits
    if sim.plant.torque_limit is not None and sim.plant.torque_limit != limits.motor_torque:
        limits = replace(limits, motor_torque=sim.plant.torque_limit)
    geom = platform_option(platform)
    nominal = _params(params)
    try:
        results = [make_plan(geom, rectangle, duration, params=nominal, limits=limits, settings=one)
                   for one in plan_settings]
        result = results[0] if len(results) == 1 else combine(results, searches)
    except (TrajectoryError, ValueError) as exc:
        raise fail(str(exc)) from exc
    verification = None
    if verify > 0:
        import os

        from agvdyn.plan_check import verify_plan

        try:
            result, verification = verify_plan(result, verify, settings=sim, plants=plants,
                                               plant_seeds=VERIFY_PLANT_SEEDS, workers=min(2, os.cpu_count() or 1),
                                               engine=verify_engine)
        except Exception as exc:  # noqa: BLE001 - the default sequence not identified, a limit broken, ...
            raise fail(f"--verify: the check on the simulator failed ({type(exc).__name__}: {exc}); "
                       "plan with --verify 0 to skip it") from exc
    try:
        written = write_text_atomically(out, yaml.safe_dump(result.to_yaml_dict(), sort_keys=False))
        if figure is not None:
            from agvdyn.trajectories.planner import plan_figure

            fig = plan_figure(result)
            fmt = figure.suffix.lower().lstrip(".") or "png"  # the temporary file's suffix says nothing
            write_atomically(figure, lambda tmp: fig.savefig(tmp, dpi=120, format=fmt))
    except (OSError, ValueError) as exc:
        raise fail(f"cannot write the plan: {exc}") from exc
    if as_json:
        data = result.to_dict()
        data["out"] = str(written)
        data["verification"] = None if verification is None else verification.to_dict()
        typer.echo(json.dumps(data, indent=2))
        return
    console = Console()
    ev, ref = result.evaluation, result.reference
    table = Table(title=f"Planned identification sequence ({result.objective}) next to the default sequence in "
                        f"{rectangle.length:g} m x {rectangle.width:g} m")
    for col in ("", "plan", "default"):
        table.add_column(col, justify="left" if not col else "right")
    table.add_row("cond(Theta_1w^T Theta_1w)", f"{ev.cond:.2f}", f"{ref.cond:.2f}")
    table.add_row("floor used (m)", f"{ev.floor.length:.2f} x {ev.floor.width:.2f}",
                  f"{ref.floor.length:.2f} x {ref.floor.width:.2f}")
    table.add_row("duration (s)", f"{ev.duration:.1f}", f"{ref.duration:.1f}")
    table.add_row("peak feed-forward torque (N m)", f"{ev.peak_torque:.2f}", f"{ref.peak_torque:.2f}")
    for name in FREE:
        table.add_row(f"predicted std {name}", f"{ev.std[name]:.4g} ({100 * ev.relative_std[name]:.2f} %)",
                      f"{ref.std[name]:.4g} ({100 * ref.relative_std[name]:.2f} %)")
    console.print(table)
    phases = Table(title="Phases (one period of a Fourier series each, at rest at both ends)")
    for col in ("phase", "mode", "duration s", "harmonics", "peak position", "peak velocity", "peak acceleration",
                "limited by"):
        phases.add_column(col, justify="left" if col in ("phase", "mode", "limited by") else "right")
    for p in result.phases:
        phases.add_row(p.name, p.mode, f"{p.duration:.1f}", str(p.harmonics), f"{p.peak_position:.3g}",
                       f"{p.peak_velocity:.3g}", f"{p.peak_acceleration:.3g}", p.limiting)
    console.print(phases)
    if verification is not None:
        _print_verification(console, verification)
    where = "MuJoCo" if verification is not None and verification.engine == "mujoco" else "the simulator"
    checked = "" if verification is None else f", checked on {where} in {verification.elapsed:.1f} s"
    console.print(f"planned in {result.elapsed:.1f} s from {len(result.starts)} starts{checked}; wrote {written}"
                  + (f" and {figure}" if figure is not None else ""))
    for warning in result.warnings + (verification.warnings if verification is not None else ()):
        console.print(f"[yellow]warning:[/yellow] {warning}", highlight=False)


def _plants(text: str) -> tuple[str, ...]:
    """``--verify-plants``: names of plant variants, or none."""
    from agvdyn.plan_check import NOMINAL, PLANT_VARIANTS

    names = tuple(n.strip() for n in text.split(",") if n.strip() and n.strip().lower() != "none")
    bad = [n for n in names if n not in PLANT_VARIANTS and n != NOMINAL]
    if bad:
        raise ValueError(f"--verify-plants {text}: unknown {', '.join(bad)}; expected none or some of "
                         f"{', '.join(PLANT_VARIANTS)}")
    return tuple(n for n in names if n != NOMINAL)


def _print_verification(console: Console, verification) -> None:
    """The candidates measured on the simulator next to their prediction (``--verify``)."""
    seeds = verification.seeds
    on = f"seed {seeds[0]}" if len(seeds) == 1 else f"seeds {seeds[0]}-{seeds[-1]} (means)"
    engine = " on MuJoCo" if verification.engine == "mujoco" else ""
    table = Table(title=f"Candidates simulated{engine} and identified on {on}, std ratios "
                        f"to the default sequence (cond {verification.default_cond:.2f}); score <= 1 meets the bars")
    columns = ["start", "predicted objective", "predicted cond", "cond", "predicted worst ratio", "worst ratio",
               "max error %"]
    if verification.plants:
        columns.append(f"score on {', '.join(verification.plants)} (seeds {', '.join(map(str, verification.plant_seeds))})")
    for col in (*columns, "score", ""):
        table.add_column(col, justify="right")
    for c in verification.candidates:
        pw = max(c.predicted_ratio, key=c.predicted_ratio.get)
        measured = (f"{c.ratio[c.worst]:.2f} ({c.worst})" if c.failure is None else c.failure[:40])
        row = [f"{c.search} {c.start}".strip(), f"{c.objective_value:.3g}", f"{c.predicted_cond:.2f}", f"{c.cond:.2f}",
               f"{c.predicted_ratio[pw]:.2f} ({pw})", measured, f"{max(c.error.values(), default=float('nan')):.1f}"]
        if verification.plants:
            row.append(", ".join(f"{c.plants[p]['score']:.3f}" if p in c.plants else "-" for p in verification.plants))
        table.add_row(*row, f"{c.score:.3f}", "chosen" if c.rank == verification.chosen else "")
    console.print(table)
