"""Command ``agvdyn export``: the identified vehicle as an MJCF or URDF model (agvdyn.export)."""
from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import List, Optional

import typer

from agvdyn.cli._app import app, fail, numbers_by_name, platform_option
from agvdyn.cli._outputs import refuse_overwrite


class _Format(str, Enum):
    """--format of ``agvdyn export`` (agvdyn.export.FORMATS)."""

    mjcf = "mjcf"
    urdf = "urdf"


def _split(items: Optional[List[str]]):
    """A BodySplit from ``KEY=VALUE`` items (unknown keys and bad values are named errors)."""
    from agvdyn.simulation.mujoco_model import BodySplit

    values = numbers_by_name("--split", items, BodySplit.__dataclass_fields__)
    try:
        return BodySplit(**values)
    except ValueError as exc:
        raise fail(f"--split: {exc}") from exc


@app.command()
def export(
    params: Path = typer.Argument(..., help="Parameter file (YAML/JSON), e.g. written by 'agvdyn identify'."),
    fmt: _Format = typer.Option(..., "--format", help="mjcf (MuJoCo; 'agvdyn simulate --engine mujoco --mjcf' "
                                "runs it) or urdf (ROS, Gazebo, Drake: <inertial>, <dynamics damping friction>)."),
    out: Path = typer.Option(..., "--out", help="Model file to write (e.g. vehicle.xml, vehicle.urdf)."),
    platform: Optional[Path] = typer.Option(None, help="Platform file (YAML); default: the platform stored in "
                                            "the parameter file, else the built-in prototype."),
    split: Optional[List[str]] = typer.Option(None, "--split", help="How the lumped parameters divide between "
                                              "bodies, KEY=VALUE (repeatable): unit_mass_fraction (0.03), "
                                              "wheel_spin_share (0.3), wheel_width (0.5), chassis_height (0.3), "
                                              "com_height (r); see docs/simulation.md."),
) -> None:
    """Write the vehicle of a parameter file as a simulator model (MJCF or URDF) with the lumped parameters kept exactly."""
    from agvdyn.cli.sim_commands import _parameter_file
    from agvdyn.export import write_vehicle_model
    from agvdyn.platform import platform_of_parameters

    refuse_overwrite({"--out": out}, {"PARAMS": params, "--platform": platform}, {"--out": "model"})
    content = _parameter_file(params)
    geom, warning = platform_of_parameters(content, None if platform is None else platform_option(platform))
    if warning is not None:
        typer.secho(f"warning: {warning}", fg=typer.colors.YELLOW, err=True)
    body_split = _split(split)
    try:
        path = write_vehicle_model(out, content.parameters, geom, fmt.value, body_split)
    except (ValueError, OSError) as exc:
        raise fail(str(exc)) from exc
    typer.echo(f"wrote {path} ({fmt.value}, {geom.describe()}, m_ch = {content.parameters.m_ch:g} kg)")
