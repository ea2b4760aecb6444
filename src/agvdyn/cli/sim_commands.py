"""Commands ``agvdyn simulate`` and ``agvdyn feedforward`` (paper sec. 5, 6.2, 7)."""
from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from agvdyn._files import write_atomically
from agvdyn.cli._app import app, fail, platform_option
from agvdyn.cli._outputs import LOG_AND_SIDECAR, refuse_overwrite, sidecar_of, trajectory_input

_EXPERIMENT_HELP = ("identification, lane-change, lateral, lifted-wheel, car-like, driving, or a trajectory file (.csv / .yaml, "
                    "see docs/simulation.md).")


def _parameter_file(path: Path) -> "ParameterFile":  # noqa: F821
    """The contents of a --params file; a bad file (missing, a directory, not YAML/JSON, not a
    parameter file) is a named error, never a traceback."""
    from agvdyn.platform import PlatformFileError, read_parameters

    try:
        return read_parameters(path)
    except PlatformFileError as exc:
        raise fail(str(exc)) from exc
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise fail(f"{path}: cannot be read as a parameter file: {exc}") from exc


def _params(path: Optional[Path], default=None):
    """The parameters of a --params file; without one, ``default`` (None: Table 2 of the paper)."""
    if path is None:
        if default is None:
            from agvdyn.platform import PAPER_PARAMETERS

            return PAPER_PARAMETERS
        return default
    return _parameter_file(path).parameters


def _output(path: Path) -> Path:
    if path.suffix.lower() not in (".parquet", ".csv"):
        raise fail(f"--out {path}: unknown suffix {path.suffix!r}: expected .parquet or .csv")
    return path


def _tracking_table(result) -> Table:
    table = Table(title=f"Tracking and odometry drift: {result.experiment}")
    cols = {"segment": "segment", "steering_max": "steer\nmrad", "wheel_speed_rms": "wheel\nmrad/s",
            "speed_rms": "speed\nmm/s", "position_error": "pose\nmm", "heading_error": "head.\nmrad",
            "odometry_drift": "odo\nmm", "saturated": "sat.\n%"}
    scale = {"steering_max": 1e3, "wheel_speed_rms": 1e3, "speed_rms": 1e3, "position_error": 1e3,
             "heading_error": 1e3, "odometry_drift": 1e3, "saturated": 100}
    for key, title in cols.items():
        table.add_column(title, justify="left" if key == "segment" else "right")
    for row in result.tracking_rows():  # dicts: no pandas
        table.add_row(row["segment"], *(f"{row[k] * scale[k]:.1f}" for k in cols if k != "segment"))
    return table


class _Plant(str, Enum):
    """--engine of ``agvdyn simulate`` (agvdyn.simulation.ENGINES)."""

    ours = "ours"
    mujoco = "mujoco"


@app.command()
def simulate(
    experiment: str = typer.Argument(..., help=_EXPERIMENT_HELP),
    out: Path = typer.Option(..., "--out", help="Log to write (.parquet or .csv) plus its YAML sidecar <out>.yaml."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the built-in prototype."),
    params: Optional[Path] = typer.Option(None, help="True parameters of the simulated vehicle (YAML/JSON); "
                                                    "default: Table 2 of the paper with B_w = 0.121."),
    controller_params: Optional[Path] = typer.Option(None, help="The controller's parameter estimate for the "
                                                               "feed-forward; default: the true parameters."),
    seed: int = typer.Option(0, help="Seed of the sensor noise; equal seeds give equal logs."),
    settings: Optional[Path] = typer.Option(None, help="Simulation settings (YAML: plant, controller, sensors, "
                                                      "limits; see docs/simulation.md)."),
    ideal_plant: bool = typer.Option(False, "--ideal-plant", help="Switch the neglected effects off (tanh "
                                     "friction, no unit masses, no torque limit, exact wheel radii)."),
    slip: bool = typer.Option(False, "--slip", help="Switch the default wheel-slip scenario on (slippery floor "
                              "and motor torque bursts in the straight and rotation of 'identification'; "
                              "replaces a slip group of --settings; see docs/simulation.md)."),
    quiet: bool = typer.Option(False, "--quiet", help="No progress bar and no table."),
    engine: _Plant = typer.Option("ours", "--engine", help="The plant: ours (tyre slip, plant.py) or mujoco (an "
                                  "MJCF generated from --platform and --params, written beside the log as "
                                  "<out>.mjcf.xml; see docs/simulation.md)."),
    mjcf: Optional[Path] = typer.Option(None, "--mjcf", help="With --engine mujoco: run this MJCF (e.g. from "
                                        "'agvdyn export') instead; it holds platform and true parameters."),
    payload: Optional[list[str]] = typer.Option(None, "--payload", help="T:MASS[:X,Y[:C]] pick-up of MASS kg at "
                                                "T s at (X, Y) m in the chassis frame with yaw inertia C kg m^2 "
                                                "about its centre (negative mass: drop); repeatable; either "
                                                "engine (MuJoCo: a body welded to the chassis); sidecar: "
                                                "payload_truth."),
    breakaway: Optional[list[str]] = typer.Option(None, "--breakaway", help="GROUP=RATIO[:W_S] breakaway "
                                                  "friction of joint group l (left steering), r (right "
                                                  "steering), w (wheels) or all: static level RATIO times "
                                                  "the sliding d_c, Stribeck velocity W_S rad/s (default: "
                                                  "the settings' stribeck_velocity); repeatable, later ones "
                                                  "win; either engine (our plant with stiction; MuJoCo: "
                                                  "static frictionloss plus a Stribeck assist, not on "
                                                  "jacks); sidecar: true_model."),
    torque_delay: Optional[float] = typer.Option(None, "--torque-delay", help="Seconds the logged torque "
                                                 "columns lag the angles (>= 0; sub-sample delays "
                                                 "interpolated); the motion is unchanged; sidecar: "
                                                 "true_model.delay_s."),
    duration: Optional[float] = typer.Option(None, "--duration", help="driving only: length of the shift, s "
                                             "(default 300)."),
    floor: Optional[str] = typer.Option(None, "--floor", help="driving only: floor LENGTHxWIDTH in m (default "
                                        "20x10); the route is drawn with --seed."),
) -> None:
    """Simulate an experiment in closed loop (plant with tyre slip, or MuJoCo) and write the log the sensors record."""
    from dataclasses import replace

    from agvdyn.platform import SAMPLE_TIME
    from agvdyn.simulation import SLIP_SCENARIO, SLIP_THRESHOLD, SimulationSettings, read_settings, simulate as run
    from agvdyn.trajectories import TrajectoryError

    on_mujoco = engine.value == "mujoco"
    if mjcf is not None and not on_mujoco:
        raise fail(f"--mjcf {mjcf}: runs on --engine mujoco only")
    if mjcf is not None and params is not None:
        raise fail(f"--mjcf {mjcf} holds the true parameters: give no --params {params}")
    model_out = Path(str(out) + ".mjcf.xml") if on_mujoco else None
    refuse_overwrite({"--out": out, "sidecar of --out": sidecar_of(out), "MJCF beside --out": model_out},
                     {**trajectory_input(experiment), "--platform": platform, "--params": params,
                      "--controller-params": controller_params, "--settings": settings, "--mjcf": mjcf},
                     {**LOG_AND_SIDECAR, "MJCF beside --out": "model"})
    try:
        sim_settings = SimulationSettings() if settings is None else read_settings(settings)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    if ideal_plant:
        sim_settings = replace(sim_settings, plant=sim_settings.plant.ideal())
    if slip:
        sim_settings = replace(sim_settings, slip=SLIP_SCENARIO)
    if payload:
        from agvdyn.simulation.payload import parse_payload

        try:
            sim_settings = replace(sim_settings, payload=tuple(parse_payload(p) for p in payload))
        except ValueError as exc:
            raise fail(str(exc)) from exc
    sim_settings = _effects(sim_settings, breakaway or [], torque_delay, on_mujoco)
    experiment = _driving(experiment, duration, floor, seed, platform_option(platform))
    geom = platform_option(platform)
    true_params = _params(params)
    ctrl_params = None if controller_params is None else _params(controller_params)
    _output(out)
    plant = {"engine": engine.value, "mjcf": mjcf}
    console = Console(stderr=True)
    try:
        if quiet:
            result = run(experiment, platform=geom, plant_params=true_params, controller_params=ctrl_params,
                         settings=sim_settings, seed=seed, **plant)
        else:
            with Progress(TextColumn("simulating {task.description}"), BarColumn(),
                          TextColumn("{task.completed:.1f} s of motion"), TimeElapsedColumn(),
                          console=console) as bar:
                task = bar.add_task(str(getattr(experiment, "name", experiment)), total=None)

                def progress(done: int, total: int) -> None:
                    bar.update(task, completed=done * SAMPLE_TIME, total=total * SAMPLE_TIME)

                result = run(experiment, platform=geom, plant_params=true_params, controller_params=ctrl_params,
                             settings=sim_settings, seed=seed, progress=progress, **plant)
        path = result.write(out)
    except (TrajectoryError, ValueError, OSError, FloatingPointError) as exc:
        raise fail(str(exc)) from exc
    if not quiet:
        console.print(_tracking_table(result))
        fs = result.trajectory.floor_space()
        console.print(f"floor space {fs.length:.2f} m x {fs.width:.2f} m, duration {result.trajectory.duration:.1f} s")
        if sim_settings.slip.active:
            events = result.slip_intervals()
            console.print(f"true wheel slip: {len(events)} events, "
                          f"{int((result.slip_speed > SLIP_THRESHOLD).any(axis=1).sum())} samples above "
                          f"{SLIP_THRESHOLD} m/s "
                          "(sidecar: slip_truth)")
    typer.echo(f"wrote {path} ({result.trajectory.n_samples:,} samples) and {path}.yaml"
               + (f" and {model_out}" if on_mujoco else ""))


def _effects(settings, breakaway: list[str], torque_delay: Optional[float], on_mujoco: bool):
    """The settings with the --breakaway groups and the --torque-delay (issue 30); bad values are
    named errors."""
    from dataclasses import replace

    from agvdyn.simulation.plant import parse_breakaway

    plant = settings.plant
    if breakaway and not on_mujoco and plant.coulomb != "stiction":  # MuJoCo: its dry friction (mujoco_friction.py)
        raise fail(f"--breakaway {breakaway[0]!r}: needs the plant's stiction friction, not coulomb="
                   f"{plant.coulomb!r} (--ideal-plant or the settings file)")
    try:
        for text in breakaway:
            plant = plant.with_breakaway(*parse_breakaway(text))
    except ValueError as exc:
        raise fail(str(exc)) from exc
    sensors = settings.sensors
    if torque_delay is not None:
        try:
            sensors = replace(sensors, torque_delay=torque_delay)
        except ValueError:
            raise fail(f"--torque-delay {torque_delay!r}: expected a finite number of seconds >= 0") from None
    return replace(settings, plant=plant, sensors=sensors) if breakaway or torque_delay is not None else settings


def _driving(experiment: str, duration: Optional[float], floor: Optional[str], seed: int, geom):
    """The ``driving`` experiment with --duration, --floor and the route of --seed; other experiments
    unchanged (and refuse those options)."""
    if experiment.strip().lower() != "driving":
        if duration is not None or floor is not None:
            raise fail(f"--duration and --floor belong to the driving experiment, not {experiment!r}")
        return experiment
    from agvdyn.trajectories import TrajectoryError, experiment as build

    options: dict = {"seed": seed}
    if duration is not None:
        options["duration"] = duration
    if floor is not None:
        try:
            length, width = (float(x) for x in floor.lower().split("x"))
        except ValueError:
            raise fail(f"--floor {floor!r}: expected LENGTHxWIDTH in m, e.g. 20x10") from None
        options["floor"] = (length, width)
    try:
        return build("driving", geom, **options)
    except TrajectoryError as exc:
        raise fail(str(exc)) from exc


class _Engine(str, Enum):
    """--engine of ``agvdyn feedforward`` (agvdyn.ffcpp.ENGINES)."""

    python = "python"
    cpp = "cpp"


@app.command()
def feedforward(
    experiment: str = typer.Argument(..., help=_EXPERIMENT_HELP),
    params: Path = typer.Option(..., help="Parameter file (YAML/JSON) of the feed-forward, eq. (21)."),
    out: Path = typer.Option(..., "--out", help="Table to write (.csv or .parquet)."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the platform stored in "
                                            "the parameter file, else the built-in prototype."),
    no_check: bool = typer.Option(False, "--no-check", help="Write the table even if the trajectory breaks "
                                  "the velocity, acceleration or torque limits."),
    engine: _Engine = typer.Option(_Engine.python, "--engine", help="Implementation of eq. (21): python (the "
                                   "reference) or cpp (the C++ library of cpp/, see docs/cpp.md); equal to 1e-9."),
) -> None:
    """Write the planned trajectory with its feed-forward motor torques of eq. (21), one row per 2 ms."""
    from agvdyn.cli.model_commands import model_parameters_option
    from agvdyn.ffcpp import CppEngineUnavailable
    from agvdyn.platform import platform_of_parameters
    from agvdyn.simulation import feedforward_table
    from agvdyn.trajectories import Limits, TrajectoryError

    refuse_overwrite({"--out": out}, {**trajectory_input(experiment), "--params": params, "--platform": platform},
                     {"--out": "table"})
    content = _parameter_file(params)
    geom, warning = platform_of_parameters(content, None if platform is None else platform_option(platform))
    if warning is not None:
        typer.secho(f"warning: {warning}", fg=typer.colors.YELLOW, err=True)
    _output(out)
    try:
        table = feedforward_table(experiment, model_parameters_option(params, content.parameters), geom,
                                  limits=None if no_check else Limits(), engine=engine.value)
    except (TrajectoryError, ValueError, CppEngineUnavailable) as exc:
        raise fail(str(exc)) from exc
    if out.suffix.lower() == ".csv":
        write_atomically(out, lambda tmp: table.to_csv(tmp, index=False))
    else:
        write_atomically(out, lambda tmp: table.to_parquet(tmp, index=False))
    typer.echo(f"wrote {out} ({len(table):,} rows; motor torques m_fl, m_rl, m_fr, m_rr in N m)")
