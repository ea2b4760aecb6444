"""The report's "Excitation plan" section (issue 11): a small plan planned and simulated, the report
finds it by the log's sidecar or takes it from --plan, shows floor, paths, cond and predicted std;
no section without a plan; a bad --plan is a clear error naming the file."""
from __future__ import annotations

import json
import re
import shutil

import pytest
import yaml
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.io import read_log, write_log
from agvdyn.platform import PROTOTYPE, Geometry
from agvdyn.report import read_plan
from agvdyn.simulation import simulate
from agvdyn.trajectories import planner as pl

#: Numerically sensitive (BLAS, numba kernels): make test runs it again under FP_ENV2 (Makefile).
pytestmark = pytest.mark.numerics

CART = Geometry(l=0.9, b=0.6, a=0.03, r=0.08, i_G=18.0, name="cart")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A 40 s plan in 3 m x 2 m (one short start), its simulated log next to it, and copies of the log
    elsewhere: with the sidecar (plan not beside it) and without the sidecar's experiment."""
    root = tmp_path_factory.mktemp("report_plan")
    result = pl.plan(PROTOTYPE, "3x2", 40.0, settings=pl.PlanSettings(starts=1, workers=1, max_iterations=30))
    plan_path = root / "quick_plan.yaml"
    plan_path.write_text(yaml.safe_dump(result.to_yaml_dict(), sort_keys=False), encoding="utf-8")
    log = simulate(plan_path, seed=1).write(root / "ident.parquet")
    away = root / "away"
    away.mkdir()
    shutil.copy(log, away / "ident.parquet")
    shutil.copy(f"{log}.yaml", away / "ident.parquet.yaml")
    loaded = read_log(log)
    recorded = root / "recorded" / "vehicle.parquet"
    recorded.parent.mkdir()
    write_log(recorded, loaded.frame, {"platform": PROTOTYPE.to_dict()})  # as on the vehicle: no experiment
    return {"root": root, "plan": plan_path, "log": log, "away": away / "ident.parquet", "recorded": recorded,
            "result": result}


def _report(*args: str) -> tuple[dict, str]:
    result = CliRunner().invoke(app, ["report", *args, "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    return data, open(data["out"], encoding="utf-8").read()


def _section(html: str) -> str:
    match = re.search(r'<section id="plan">.*?</section>', html, flags=re.S)
    return match.group(0) if match else ""


@pytest.fixture(scope="module")
def found(files):
    """The report of the simulated log, whose plan its sidecar names."""
    return _report("--ident", str(files["log"]), "--out", str(files["root"] / "found.html"))


def test_sidecar_names_the_plan_beside_the_log(files, found):
    data, html = found
    plan = data["plan"]
    assert plan["found"] == "sidecar" and plan["path"] == str(files["plan"])
    assert plan["floor"] == {"length": 3.0, "width": 2.0} and plan["objective"] == "std"
    assert plan["cond"] == pytest.approx(files["result"].evaluation.cond)
    used = files["result"].evaluation.floor
    assert plan["floor_used"] == pytest.approx({"length": used.length, "width": used.width})
    assert set(plan["predicted_std"]) == set(pl.FREE)
    (driven,) = plan["driven"]  # the simulated vehicle drove the plan: odometry occupies the same floor
    assert driven["floor_used"]["length"] == pytest.approx(used.length, abs=0.05)
    assert driven["floor_used"]["width"] == pytest.approx(used.width, abs=0.05)
    section = _section(html)
    assert "<h2>Excitation plan</h2>" in section and "found from the log" in section
    assert section.count("<img ") == 1 and "data:image/png;base64," in section
    assert "floor available" in section and "floor the plan uses" in section and "floor driven" in section
    assert "Predicted and identified std" in section and "identified" in section
    assert 'href="#plan"' in html
    assert any(f["role"] == "plan" and f["path"] == str(files["plan"]) for f in data["provenance"]["files"])


def test_plan_given_for_a_log_recorded_without_one(files):
    out = files["root"] / "given.html"
    data, html = _report("--ident", str(files["recorded"]), "--out", str(out), "--plan", str(files["plan"]))
    assert data["plan"]["found"] == "given" and data["plan"]["path"] == str(files["plan"])
    assert [d["log"] for d in data["plan"]["driven"]] == [str(files["recorded"])]
    section = _section(html)
    assert "given with <code>--plan</code>" in section and section.count("<img ") == 1


def test_no_plan_no_section_and_a_note_when_the_plan_is_missing(files):
    data, html = _report("--ident", str(files["recorded"]), "--out", str(files["root"] / "none.html"))
    assert data["plan"] is None and 'id="plan"' not in html and 'href="#plan"' not in html
    data, html = _report("--ident", str(files["away"]), "--out", str(files["root"] / "missing.html"))
    section = _section(html)
    assert data["plan"] is None and "<img " not in section
    assert "quick_plan" in section and "--plan FILE" in section


def test_bad_plan_is_a_clear_error_naming_the_file(files, tmp_path):
    missing = tmp_path / "nope.yaml"
    result = CliRunner().invoke(app, ["report", "--ident", str(files["log"]), "--out", str(tmp_path / "r.html"),
                                      "--plan", str(missing)])
    assert result.exit_code == 2
    assert str(missing) in result.output and "no such file" in result.output
    assert not (tmp_path / "r.html").exists()
    junk = tmp_path / "junk.yaml"
    junk.write_text("just: a mapping\n", encoding="utf-8")
    with pytest.raises(ValueError, match=re.escape(str(junk)) + ".*segments"):
        read_plan(junk, PROTOTYPE)
    with pytest.raises(ValueError, match=re.escape(str(files["plan"])) + ".*platform"):
        read_plan(files["plan"], CART)


def test_plan_section_in_chromium(found):
    """The section in a real browser: its figure renders (non-blank), no horizontal scroll at 1280 px."""
    from pathlib import Path

    from test_report_browser import _IMAGES, BROWSER, Browser, image_statistics

    if BROWSER is None:
        pytest.skip("Chromium is not installed")
    out = Path(found[0]["out"])
    with Browser(BROWSER, width=1280, height=900) as browser:
        browser.open(out.resolve().as_uri())
        images = [i for i in browser.evaluate(_IMAGES) if i["alt"].startswith("Floor rectangle")]
        page = browser.evaluate("({width: document.documentElement.scrollWidth, "
                                "text: document.querySelector('#plan').innerText})")
        shots = [browser.screenshot({k: img[k] for k in ("x", "y", "width", "height")}) for img in images]
        errors = browser.errors()
    assert errors == []
    assert page["width"] <= 1280
    assert "Excitation plan" in page["text"] and "floor available" in page["text"]
    (img,) = images
    assert img["complete"] and img["naturalWidth"] > 300 and img["width"] > 300
    ink, spread = image_statistics(shots[0])
    assert 0.01 < ink < 0.9 and spread > 10


def test_a_plan_file_of_the_same_name_but_another_floor_is_not_shown(files, tmp_path):
    """The sidecar records the floor the simulated trajectory occupied: a different plan under the same
    name is left out with a note, and the report's API takes a plan for results computed elsewhere."""
    from agvdyn.identification import identify
    from agvdyn.report import excitation_plan, report_of

    side = yaml.safe_load(open(f"{files['log']}.yaml", encoding="utf-8"))
    side["floor_space"] = {"length": 9.0, "width": 9.0}
    shutil.copy(files["log"], tmp_path / "ident.parquet")
    (tmp_path / "ident.parquet.yaml").write_text(yaml.safe_dump(side), encoding="utf-8")
    shutil.copy(files["plan"], tmp_path / "quick_plan.yaml")
    log = read_log(tmp_path / "ident.parquet")
    plan, notes = excitation_plan([log], PROTOTYPE)
    assert plan is None and "another plan" in notes[0] and str(tmp_path / "quick_plan.yaml") in notes[0]
    ident = identify([read_log(files["log"])])
    report = report_of(ident, plan=files["plan"])
    assert report.plan.found == "given" and report.plan.driven == ()  # no logs given: nothing driven to draw
    assert report.to_json_dict()["plan"]["path"] == str(files["plan"])
