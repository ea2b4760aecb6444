"""Figures, HTML report and the identify / validate / report commands end to end."""
from __future__ import annotations

import base64
import json
import re

import pytest
from matplotlib.figure import Figure
from typer.testing import CliRunner

from agvdyn import plots
from agvdyn.cli import app
from agvdyn.identification import identify
from agvdyn.io import write_log
from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PROTOTYPE, read_parameters
from agvdyn.report import parameter_table, write_report
from agvdyn.validation import validate
from model_logs import identification_frame, lane_change_frame

SHORT = {"steer_left": 6.0, "steer_right": 6.0, "straight": 6.0, "rotation": 6.0}


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    ident = root / "ident.parquet"
    write_log(ident, identification_frame(SHORT)[0], {"platform": PROTOTYPE.to_dict()})
    lane = root / "lane.csv"
    write_log(lane, lane_change_frame(8.0)[0])
    straight = root / "straight.parquet"
    write_log(straight, identification_frame({"straight": 6.0})[0])
    return {"ident": ident, "lane": lane, "straight": straight, "root": root}


@pytest.fixture(scope="module")
def results(logs):
    ident = identify(logs["ident"])
    return ident, validate(logs["lane"], ident.parameters, PROTOTYPE)


def test_parameter_table_acceptance_rule(results):
    ident, _ = results
    table = parameter_table(ident)
    assert list(table.index) == list(PARAMETER_NAMES)
    assert table.loc["B_w", "ok"] is None
    assert table.drop("B_w")["ok"].all()  # noise-free model data: everything within 5 %
    off = parameter_table(ident, PAPER_PARAMETERS.replace(m_ch=2 * PAPER_PARAMETERS.m_ch))
    assert off.loc["m_ch", "ok"] == False  # noqa: E712  (50 % off and far beyond 3 std)
    assert off.loc["m_ch", "deviation_pct"] == pytest.approx(-50.0, abs=0.01)


def test_figures_are_figures_with_one_panel_per_excited_coordinate(results):
    ident, val = results
    fig5 = plots.identification_figure(ident)
    assert isinstance(fig5, Figure)
    titles = [ax.get_title() for ax in fig5.axes if ax.get_visible()]
    assert len(titles) == 4 and any(t.startswith("rotation") for t in titles)
    fig6 = plots.validation_figure(val)
    assert len([ax for ax in fig6.axes if ax.get_visible()]) == 2
    assert isinstance(plots.parameter_figure(ident), Figure)


def test_html_report_embeds_figures_and_is_atomic(results, tmp_path):
    ident, val = results
    path = write_report(tmp_path / "r.html", ident, val, inputs={"note": "<script>"})
    text = path.read_text()
    images = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", text)
    assert len(images) == 3
    assert base64.b64decode(images[0])[:8] == b"\x89PNG\r\n\x1a\n"
    assert "&lt;script&gt;" in text and "<script>" not in text  # inputs are escaped
    assert "NRMSE" in text and "11.56" in text
    assert [p.name for p in tmp_path.iterdir()] == ["r.html"]  # no temporary file left


def test_cli_identify_json_keys_and_file(logs):
    out = logs["root"] / "p.yaml"
    result = CliRunner().invoke(app, ["identify", str(logs["ident"]), "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert set(data["parameters"]) == set(PARAMETER_NAMES)
    assert set(data["parameters"]["C_l"]) == {"value", "std", "ci95", "std_classic"}
    low, high = data["parameters"]["C_l"]["ci95"]
    assert low < data["parameters"]["C_l"]["value"] < high
    assert data["uncertainty"]["method"] == "hac" and data["uncertainty"]["bandwidth_steps"] >= 50
    assert data["correlation"]["names"][0] == "C_l" and data["correlation"]["matrix"][0][0] == 1.0
    assert data["parameters"]["B_w"] == {"value": 0.121, "std": None}
    assert data["condition_number"] > 1
    assert read_parameters(out).parameters.C_ch == pytest.approx(data["parameters"]["C_ch"]["value"])


def test_cli_identify_table_validate_and_report(logs):
    runner = CliRunner()
    params = logs["root"] / "p2.yaml"
    result = runner.invoke(app, ["identify", str(logs["ident"]), "--out", str(params), "--fix", "B_w=0.121"])
    assert result.exit_code == 0, result.output
    assert "C_ch" in result.output and "wrote" in result.output
    result = runner.invoke(app, ["validate", str(logs["lane"]), "--params", str(params), "--json"])
    assert result.exit_code == 0, result.output
    nrmse = json.loads(result.output)["nrmse"]
    assert set(nrmse) == {"lane_change:alpha_v", "lane_change:x_ch"} and max(nrmse.values()) < 0.01
    report = logs["root"] / "r.html"
    result = runner.invoke(app, ["report", "--ident", str(logs["ident"]), "--validation", str(logs["lane"]),
                                 "--out", str(report)])
    assert result.exit_code == 0, result.output
    assert report.stat().st_size > 10_000


def test_cli_refusal_for_data_quality_exits_1(logs):
    result = CliRunner().invoke(app, ["identify", str(logs["straight"]), "--out", str(logs["root"] / "x.yaml")])
    assert result.exit_code == 1
    assert "refused" in result.output and "cannot be identified" in result.output
    assert not (logs["root"] / "x.yaml").exists()


@pytest.mark.parametrize("args, message", [
    (["identify", "{ident}", "--out", "{root}/x.yaml", "--segments", "straigth"], "unknown segment names ['straigth']"),
    (["identify", "{ident}", "--out", "{root}/x.yaml", "--fix", "B_x=1"], "--fix"),
    (["identify", "{ident}", "--out", "{root}/x.yaml", "--filtering", "smooth"], "filtering"),
    (["identify", "{root}/missing.parquet", "--out", "{root}/x.yaml"], "missing.parquet"),
    (["validate", "{lane}", "--params", "{root}/missing.yaml"], "missing.yaml"),
])
def test_cli_errors_exit_2(logs, args, message):
    args = [a.format(**{k: str(v) for k, v in logs.items()}) for a in args]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert message in result.output
    assert not (logs["root"] / "x.yaml").exists()
