"""``agvdyn feedforward`` uses the vehicle stored in the parameter file; ``--platform`` overrides it
with a warning; bad files given as ``--params`` or ``--platform`` are named errors (exit 2)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

import agvdyn.cli  # noqa: F401  (registers the commands)
from agvdyn.cli._app import app
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, Geometry, ParameterFile, write_parameters, write_platform

OTHER = Geometry(l=1.0, b=0.7, a=0.04, r=0.09, i_G=20.0, name="small")
TORQUES = ["m_fl", "m_rl", "m_fr", "m_rr"]
runner = CliRunner()


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    paths = {
        "params_other": tmp_path / "params_other.yaml",
        "params_proto": tmp_path / "params_proto.yaml",
        "params_none": tmp_path / "params_none.json",
        "platform_other": tmp_path / "other.yaml",
        "platform_proto": tmp_path / "proto.yaml",
    }
    write_parameters(paths["params_other"], ParameterFile(PAPER_PARAMETERS, geometry=OTHER))
    write_parameters(paths["params_proto"], ParameterFile(PAPER_PARAMETERS, geometry=PROTOTYPE))
    write_parameters(paths["params_none"], ParameterFile(PAPER_PARAMETERS))
    write_platform(paths["platform_other"], OTHER)
    write_platform(paths["platform_proto"], PROTOTYPE)
    return paths


def _feedforward(tmp_path: Path, name: str, *args: str):
    out = tmp_path / f"{name}.csv"
    res = runner.invoke(app, ["feedforward", "lane-change", "--out", str(out), *args])
    table = pd.read_csv(out) if res.exit_code == 0 else None
    return res, table


def test_the_platform_stored_in_the_parameter_file_is_used(tmp_path, files):
    res_other, other = _feedforward(tmp_path, "other", "--params", str(files["params_other"]))
    assert res_other.exit_code == 0, res_other.output
    assert "warning" not in res_other.stderr
    res_proto, proto = _feedforward(tmp_path, "proto", "--params", str(files["params_proto"]))
    assert res_proto.exit_code == 0, res_proto.output
    # same parameters, other vehicle: other torques (and another trajectory: other wheel radius)
    assert not other[TORQUES].equals(proto[TORQUES])
    res_given, given = _feedforward(tmp_path, "given", "--params", str(files["params_other"]),
                                    "--platform", str(files["platform_other"]))
    assert res_given.exit_code == 0, res_given.output
    assert "warning" not in res_given.stderr
    pd.testing.assert_frame_equal(other, given)


def test_no_stored_platform_is_the_prototype_with_a_warning(tmp_path, files):
    res_none, none = _feedforward(tmp_path, "none", "--params", str(files["params_none"]))
    assert res_none.exit_code == 0, res_none.output
    assert res_none.stderr.startswith("warning: ") and "prototype" in res_none.stderr
    _, proto = _feedforward(tmp_path, "proto", "--params", str(files["params_proto"]))
    pd.testing.assert_frame_equal(none, proto)


def test_platform_option_overrides_with_a_warning(tmp_path, files):
    res, table = _feedforward(tmp_path, "override", "--params", str(files["params_other"]),
                              "--platform", str(files["platform_proto"]))
    assert res.exit_code == 0, res.output
    assert res.stderr.startswith("warning: ") and "differs" in res.stderr
    _, proto = _feedforward(tmp_path, "proto", "--params", str(files["params_proto"]))
    pd.testing.assert_frame_equal(table, proto)


def _bad_files(tmp_path: Path) -> dict[str, Path]:
    from agvdyn.simulation import SimulationSettings, simulate
    from agvdyn.trajectories import lane_change

    log = simulate(lane_change(length=1.0, offset=0.2, straight_before=0.1, straight_after=0.1),
                   settings=SimulationSettings(check_limits=False))
    parquet = log.write(tmp_path / "log.parquet")
    csv = log.write(tmp_path / "log.csv")
    not_yaml = tmp_path / "broken.yaml"
    not_yaml.write_text("l: [1.0, 2\nb: {", encoding="utf-8")
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\xff\xfe\x00\x81 not text")
    directory = tmp_path / "a_directory"
    directory.mkdir()
    return {"missing": tmp_path / "missing.yaml", "directory": directory, "not_yaml": not_yaml,
            "binary": binary, "parquet_log": parquet, "csv_log": csv, "sidecar": Path(f"{parquet}.yaml")}


@pytest.mark.parametrize("option", ["--params", "--platform"])
def test_bad_files_are_named_errors(tmp_path, files, option):
    for kind, bad in _bad_files(tmp_path).items():
        args = ["--params", str(bad)] if option == "--params" else ["--params", str(files["params_other"]),
                                                                    "--platform", str(bad)]
        res, _ = _feedforward(tmp_path, f"bad_{kind}", *args)
        assert res.exit_code == 2, (kind, res.output)
        assert isinstance(res.exception, SystemExit), (kind, res.exception)
        assert res.stderr.startswith(f"error: {bad}: "), (kind, res.stderr)
        assert "Traceback" not in res.output
        assert not (tmp_path / f"bad_{kind}.csv").exists()
