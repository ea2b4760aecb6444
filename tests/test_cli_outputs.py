"""No command writes over one of its inputs (issue 26, item 2).

Every writing command refuses, with exit code 2 before any work, an output that is the same file as one
of its inputs (by path, symlink or hard link; a log's sidecar and a file inside a bag directory included)
or as another of its outputs, and a parameter file, plan, report or figure named like a log (.parquet,
.csv, .db3, .mcap). Each test checks that the inputs keep their bytes and modification time.
"""
from __future__ import annotations

import functools
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.io import Log, read_mapping, write_bag, write_log
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, ParameterFile, write_parameters, write_platform
from model_logs import identification_frame

MAPPINGS = Path(__file__).resolve().parents[1] / "examples" / "mappings"
runner = CliRunner()


@functools.lru_cache(maxsize=1)
def _frame() -> pd.DataFrame:
    frame, _ = identification_frame({"steer_left": 3.0, "steer_right": 3.0, "straight": 3.0, "rotation": 3.0})
    return frame


@pytest.fixture()
def inputs(tmp_path: Path) -> dict[str, Path]:
    """Small real inputs of every kind, in ``tmp_path``."""
    paths = {
        "log": write_log(tmp_path / "run.parquet", _frame(), {"source": "test"}),
        "csv": write_log(tmp_path / "run.csv", _frame()),
        "platform": write_platform(tmp_path / "proto.yaml", PROTOTYPE),
        "params": write_parameters(tmp_path / "params.yaml", ParameterFile(PAPER_PARAMETERS, geometry=PROTOTYPE)),
        "mapping": Path(shutil.copy(MAPPINGS / "identity.yaml", tmp_path / "mapping.yaml")),
        "settings": tmp_path / "settings.yaml",
        "trajectory": tmp_path / "traj.csv",
        "plan": tmp_path / "plan.yaml",
        "manifest": tmp_path / "fleet.yaml",
    }
    paths["sidecar"] = tmp_path / "run.parquet.yaml"
    paths["settings"].write_text("limits: {}\n", encoding="utf-8")
    t = np.linspace(0.0, 2.0, 41)
    pd.DataFrame({"t": t, "mode": "2s", "alpha_l": 0.0, "alpha_r": 0.0,
                  "x_ch": 0.1 * (1 - np.cos(np.pi * t))}).to_csv(paths["trajectory"], index=False)
    paths["plan"].write_text("plan: {floor: {length: 5.0, width: 3.0}}\n"
                             "segments:\n  - name: straight\n    mode: straight\n"
                             "    fourier: {base_frequency: 2.0, a: [0.3, -0.1], b: [0.1, 0.2]}\n", encoding="utf-8")
    paths["manifest"].write_text(yaml.safe_dump({"jobs": [{"name": "agv-a", "logs": ["run.parquet"]}]}),
                                 encoding="utf-8")
    return paths


def _snapshot(paths) -> dict[Path, tuple[bytes, int]]:
    files = []
    for p in paths:
        files += sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in files}


def _refused(args: list[str], inputs: dict[str, Path], *texts: str, extra=()) -> None:
    """The command exits with 2 naming every text, and every input keeps its bytes and mtime."""
    before = _snapshot([*inputs.values(), *extra])
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 2, res.output
    for text in texts:
        assert str(text) in res.output, res.output
    assert _snapshot([*inputs.values(), *extra]) == before


def _link(target: Path, link: Path, hard: bool = False) -> Path:
    os.link(target, link) if hard else link.symlink_to(target)
    return link


# ---- identify: the reported bug and its relatives


def test_identify_refuses_to_write_the_parameters_over_its_log(inputs):
    log = inputs["log"]
    _refused(["identify", log, "--out", log], inputs, log, "LOG", "overwrite the input")


@pytest.mark.parametrize("case", ["sidecar", "symlink", "hardlink", "mapping", "platform"])
def test_identify_refuses_the_other_ways_onto_an_input(inputs, tmp_path, case):
    log = inputs["log"]
    args = ["identify", log]
    if case == "sidecar":  # the YAML next to the log is read with it
        out, role = inputs["sidecar"], "sidecar of LOG"
    elif case == "symlink":
        out, role = _link(log, tmp_path / "link.yaml"), "LOG"
    elif case == "hardlink":
        out, role = _link(inputs["platform"], tmp_path / "hard.yaml", hard=True), "--platform"
        args += ["--platform", inputs["platform"]]
    elif case == "mapping":
        out, role = inputs["mapping"], "--mapping"
        args += ["--mapping", inputs["mapping"]]
    else:
        out, role = inputs["platform"], "--platform"
        args += ["--platform", inputs["platform"]]
    _refused([*args, "--out", out], inputs, out, role)


def test_identify_refuses_a_parameter_file_named_like_a_log(inputs, tmp_path):
    for name in ("params.csv", "params.PARQUET", "params.mcap", "params.db3"):
        out = tmp_path / name
        _refused(["identify", inputs["log"], "--out", out], inputs, out, "log")
        assert not out.exists()


# ---- the other commands, one test each


def test_validate_writes_nothing(inputs, tmp_path):
    """validate has no output option: it only reads (listed in the table of docs/cli.md)."""
    before = _snapshot(inputs.values())
    listing = sorted(tmp_path.iterdir())
    runner.invoke(app, ["validate", str(inputs["log"]), "--params", str(inputs["params"])])
    assert _snapshot(inputs.values()) == before and sorted(tmp_path.iterdir()) == listing


@pytest.mark.parametrize("case", ["log", "reference", "plan", "sidecar-plan", "outputs", "suffix"])
def test_report(inputs, tmp_path, case):
    log, html = inputs["log"], tmp_path / "report.html"
    if case == "sidecar-plan":  # a simulated log whose sidecar names the plan it was driven from
        from agvdyn.simulation import simulate

        sim = simulate(inputs["plan"], seed=1).write(tmp_path / "sim.parquet")
        inputs = {**inputs, "sim": sim}
    args = ["report", "--ident", log, *(("--ident", inputs["sim"]) if case == "sidecar-plan" else ())]
    if case == "log":
        args += ["--out", log]
        texts = (log, "--ident")
    elif case == "reference":
        args += ["--out", html, "--reference", inputs["params"], "--params-out", inputs["params"]]
        texts = (inputs["params"], "--reference")
    elif case == "plan":
        args += ["--out", html, "--plan", inputs["plan"], "--params-out", inputs["plan"]]
        texts = (inputs["plan"], "--plan")
    elif case == "sidecar-plan":  # found only once the logs are read, still before anything is written
        args += ["--out", html, "--params-out", inputs["plan"]]
        texts = (inputs["plan"], "plan file named by a log's sidecar")
    elif case == "outputs":  # two outputs on one file
        args += ["--out", html, "--params-out", html]
        texts = (html, "--out", "--params-out")
    else:
        args += ["--out", tmp_path / "report.parquet"]
        texts = (tmp_path / "report.parquet", "log")
    _refused(args, inputs, *texts)
    assert not html.exists() and not (tmp_path / "report.parquet").exists()


@pytest.mark.parametrize("case", ["same", "symlink", "sidecar", "bag"])
def test_convert(inputs, tmp_path, case):
    source, extra = inputs["csv"], ()
    if case == "same":
        args, texts = ["convert", source, "--out", source], (source, "INPUT", "overwrite the input")
    elif case == "symlink":
        out = _link(source, tmp_path / "link.parquet")
        args, texts = ["convert", source, "--out", out], (out, "INPUT")
    elif case == "sidecar":  # <out>.yaml, written beside the log, is the mapping file
        mapping = Path(shutil.copy(inputs["mapping"], tmp_path / "conv.csv.yaml"))
        extra = (mapping,)
        args, texts = ["convert", source, "--mapping", mapping, "--out", tmp_path / "conv.csv"], (mapping, "--mapping")
    else:  # a log written into the bag directory it is converted from
        mapping = MAPPINGS / "ros2_control.yaml"
        bag = write_bag(Log.from_frame(_frame().iloc[:500]), tmp_path / "bag", read_mapping(mapping), "mcap",
                        platform=PROTOTYPE)
        extra = (bag,)
        args = ["convert", bag, "--mapping", mapping, "--platform", inputs["platform"], "--out", bag / "run.parquet"]
        texts = (bag / "run.parquet", "INPUT")
    _refused(args, inputs, *texts, extra=extra)


@pytest.mark.parametrize("case", ["trajectory", "sidecar", "settings"])
def test_simulate(inputs, tmp_path, case):
    traj = inputs["trajectory"]
    if case == "trajectory":
        args, texts = ["simulate", traj, "--out", traj], (traj, "trajectory")
    elif case == "sidecar":  # <out>.yaml is the --params file
        params = Path(shutil.copy(inputs["params"], tmp_path / "sim.csv.yaml"))
        args, texts = ["simulate", traj, "--params", params, "--out", tmp_path / "sim.csv"], (params, "--params")
        inputs = {**inputs, "sim_params": params}
    else:
        out = _link(inputs["settings"], tmp_path / "sim.parquet")
        args, texts = ["simulate", traj, "--settings", inputs["settings"], "--out", out], (out, "--settings")
    _refused([*args, "--quiet"], inputs, *texts)


@pytest.mark.parametrize("case", ["trajectory", "hardlink"])
def test_feedforward(inputs, tmp_path, case):
    traj = inputs["trajectory"]
    out = traj if case == "trajectory" else _link(inputs["params"], tmp_path / "ff.csv", hard=True)
    role = "trajectory" if case == "trajectory" else "--params"
    _refused(["feedforward", traj, "--params", inputs["params"], "--out", out], inputs, out, role)


@pytest.mark.parametrize("case", ["params", "settings", "figure-out", "figure-suffix"])
def test_plan(inputs, tmp_path, case):
    args = ["plan", "--verify", "0", "--starts", "1", "--search", "narrow"]
    if case == "params":
        args += ["--params", inputs["params"], "--out", inputs["params"]]
        texts = (inputs["params"], "--params")
    elif case == "settings":
        args += ["--settings", inputs["settings"], "--out", inputs["settings"]]
        texts = (inputs["settings"], "--settings")
    elif case == "figure-out":
        out = tmp_path / "new.yaml"
        args += ["--out", out, "--figure", out]
        texts = (out, "--figure")
    else:
        args += ["--out", tmp_path / "new.yaml", "--figure", tmp_path / "fig.csv"]
        texts = (tmp_path / "fig.csv", "log")
    _refused(args, inputs, *texts)
    assert not (tmp_path / "new.yaml").exists()


@pytest.mark.parametrize("case", ["log", "manifest"])
def test_batch(inputs, tmp_path, case):
    if case == "log":  # a log the manifest names
        out, role = inputs["log"], "agv-a"
    else:
        out, role = _link(inputs["manifest"], tmp_path / "fleet.parquet"), "MANIFEST"
    _refused(["batch", inputs["manifest"], "--out", out, "--workers", "1", "--quiet"], inputs, out, role)


@pytest.mark.parametrize("case", ["settings", "trajectory"])
def test_montecarlo(inputs, tmp_path, case):
    args = ["montecarlo", "--runs", "2", "--workers", "1", "--experiment", inputs["trajectory"]]
    if case == "settings":
        out = _link(inputs["settings"], tmp_path / "study.parquet", hard=True)
        args += ["--settings", inputs["settings"]]
        role = "--settings"
    else:
        out, role = _link(inputs["trajectory"], tmp_path / "study.parquet"), "trajectory"
    _refused([*args, "--out", out], inputs, out, role)


# ---- the check itself


def test_check_outputs_rules(tmp_path):
    from agvdyn._files import OutputPathError, check_outputs

    log = tmp_path / "run.parquet"
    log.write_bytes(b"log")
    bag = tmp_path / "bag"
    bag.mkdir()
    # logs and tables may carry a log's suffix; new outputs apart from the inputs pass
    check_outputs({"--out": tmp_path / "new.parquet", "sidecar of --out": tmp_path / "new.parquet.yaml"},
                  {"LOG": log, "BAG": bag, "--platform": None}, kinds={"--out": "log"})
    check_outputs({"--out": tmp_path / "p.yaml"}, {"LOG": log})
    cases = [
        ({"--out": log}, {"LOG": log}, "overwrite the input"),
        ({"--out": tmp_path / "." / "sub" / ".." / "run.parquet"}, {"LOG": log}, "overwrite the input"),
        ({"--out": tmp_path / "later.yaml"}, {"--mapping": tmp_path / "later.yaml"}, "overwrite the input"),
        ({"--out": bag}, {"BAG": bag}, "overwrite the input"),
        ({"--out": bag / "x.parquet"}, {"BAG": bag}, "inside the input directory"),
        ({"--out": tmp_path / "a.yaml", "--figure": tmp_path / "a.yaml"}, {}, "--out"),
        ({"--out": tmp_path / "p.csv"}, {}, "log"),
    ]
    for outputs, inputs, text in cases:
        with pytest.raises(OutputPathError, match=text) as info:
            check_outputs(outputs, inputs, kinds={"--out": "parameter file"})
        assert isinstance(info.value, ValueError) and str(next(iter(outputs.values()))) in str(info.value)
