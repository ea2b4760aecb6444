"""Issue 26, item 6: ``identify``, ``validate``, ``inspect`` and ``batch`` are readable at 80 columns.

Each command runs through the typer app with ``COLUMNS`` set (rich reads it, as in a terminal):
no printed line is wider, no value is cut with an ellipsis, and the printed values parse back
to the ``--json`` values at their printed precision. ``inspect`` merges flickering mode runs in
its printed timeline (``--min-run``) and keeps its ``--json`` as it was.
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from rich.cells import cell_len
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.io import read_log, write_log
from agvdyn.platform import PARAMETER_NAMES, PROTOTYPE
from agvdyn.preflight import TimelineRow, merge_short_runs, preflight

runner = CliRunner()
NUMBER = r"[-+]?\d[\d,]*(?:\.\d*)?(?:e[-+]?\d+)?"


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    """A folder with a simulated identification log, a lane change, and a steering test flickering at alpha = 0."""
    from agvdyn.simulation import simulate

    root = tmp_path_factory.mktemp("width")
    simulate("identification", seed=5).write(root / "ident.parquet")
    simulate("lane-change", seed=6).write(root / "lane.parquet")
    write_log(root / "flicker.parquet", flicker_frame())
    return root


def flicker_frame(duration: float = 24.0, dt: float = 0.002) -> pd.DataFrame:
    """A steering test of the left wheel set at rest, slow enough that its noisy angle passes the
    straight configuration alpha = (0, 0) many times: the detection flickers between 1 and 2s."""
    rng = np.random.default_rng(3)
    t = np.arange(int(duration / dt)) * dt
    smooth = np.convolve(rng.standard_normal(t.size + 99), np.ones(100) / 10.0, mode="valid")  # ~0.2 s correlation
    alpha_l = 0.12 * np.sin(2 * np.pi * t / 12.0) + 0.012 * smooth
    alpha_r = 0.004 * np.convolve(rng.standard_normal(t.size + 99), np.ones(100) / 10.0, mode="valid")
    data = {"t": t, "alpha_l": alpha_l, "alpha_r": alpha_r}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"beta_{w}"] = 0.05 * (k % 2 * 2 - 1) * alpha_l  # the wheels roll a little as the set steers
        data[f"m_{w}"] = 0.5 * np.sin(t + k)
    frame = pd.DataFrame(data)
    frame["segment"] = "steer_left"
    return frame


def run(args: list[str], columns: int, folder: Path):
    """The command in ``folder`` (short relative paths, as a user types them) at ``columns`` wide."""
    here = os.getcwd()
    os.chdir(folder)
    try:
        result = runner.invoke(app, args, env={"COLUMNS": str(columns), "TERM": "xterm"})
    finally:
        os.chdir(here)
    assert result.exit_code == 0, result.output
    return result.output


def check_fits(text: str, columns: int) -> list[str]:
    lines = text.splitlines()
    wide = [line for line in lines if cell_len(line) > columns]
    assert not wide, f"{len(wide)} lines wider than {columns}:\n" + "\n".join(wide[:5])
    assert "…" not in text, "a value cut with an ellipsis:\n" + "\n".join(line for line in lines if "…" in line)
    return lines


def numbers(line: str) -> list[float]:
    return [float(x.replace(",", "")) for x in re.findall(NUMBER, line)]


def row_of(lines: list[str], key: str) -> list[str]:
    """The printed lines whose first cell is ``key`` (box characters of any table style ignored)."""
    return [line.strip(" │┃").strip() for line in lines if line.strip(" │┃").split()[:1] == [key]]


@pytest.fixture(scope="module")
def identified(logs) -> dict:
    out = run(["identify", "ident.parquet", "--out", "p.json", "--json"], 80, logs)
    return json.loads(out)


@pytest.mark.parametrize("columns", [80, 100, 200])
def test_identify_table_fits_and_keeps_every_digit_it_prints(logs, identified, columns):
    lines = check_fits(run(["identify", "ident.parquet", "--out", "p.yaml"], columns, logs), columns)
    for name in PARAMETER_NAMES:
        entry = identified["parameters"][name]
        rows = row_of(lines, name)
        assert len(rows) == 1, f"{name}: one row expected, got {rows}"
        got = numbers(rows[0][len(name):])
        assert got[0] == pytest.approx(entry["value"], rel=1e-5), rows[0]  # 6 significant digits
        if entry["std"] is None:
            assert "fixed" in rows[0]
            continue
        assert got[1] == pytest.approx(entry["std"], rel=6e-3), rows[0]  # 3 significant digits
        assert got[2:4] == pytest.approx(entry["ci95"], rel=1e-4), rows[0]  # 5 significant digits
    if columns >= 200:  # a wide terminal shows every column
        text = "\n".join(lines)
        assert "std eq. 25" in text and "Table 2" in text and "deviation" in text
        assert "not shown" not in text


@pytest.mark.parametrize("columns", [80, 200])
def test_validate_table_fits(logs, identified, columns):
    lines = check_fits(run(["validate", "lane.parquet", "--params", "p.json"], columns, logs), columns)
    data = json.loads(run(["validate", "lane.parquet", "--params", "p.json", "--json"], columns, logs))
    for key, value in data["nrmse"].items():
        rows = row_of(lines, key)
        assert len(rows) == 1, f"{key}: {lines}"
        got = numbers(rows[0][len(key):])
        assert got[0] == pytest.approx(value, rel=1e-3)  # 4 significant digits
        assert got[1] == pytest.approx(data["nrmse_without_stiction"][key], rel=1e-3)


@pytest.mark.parametrize("columns", [80, 100, 200])
def test_inspect_fits(logs, columns):
    check_fits(run(["inspect", "ident.parquet", "flicker.parquet"], columns, logs), columns)


MODE_ROW = re.compile(r"^\s*(\d\w?) [a-z_]+\s+(\d+\.\d{3})\s+(\d+\.\d{3})\s+(\d+\.\d{3})")


def test_inspect_merges_flickering_runs_in_print_only(logs):
    raw = json.loads(run(["inspect", "flicker.parquet", "--json", "--min-duration", "0"], 80, logs))
    assert raw["detected_runs"] == len(raw["modes"]) > 40  # the log flickers
    default = run(["inspect", "flicker.parquet", "--json"], 80, logs)
    assert json.loads(default)["detected_modes"] == raw["modes"]  # every run in --json, whatever --min-duration
    assert run(["inspect", "flicker.parquet", "--json", "--min-run", "0"], 80, logs) == default
    assert run(["inspect", "flicker.parquet", "--json", "--min-run", "2"], 80, logs) == default

    lines = check_fits(run(["inspect", "flicker.parquet", "--min-run", "0.5"], 80, logs), 80)
    rows = [m for m in map(MODE_ROW.match, lines) if m]
    assert 1 < len(rows) < 20
    assert any(line.startswith(f"merged {len(raw['modes']) - len(rows)} of {len(raw['modes'])} detected runs")
               for line in lines), "\n".join(lines)
    # every run is inside a printed row, the rows in order from the first to the last sample
    assert float(rows[0].group(2)) == pytest.approx(raw["modes"][0]["start"], abs=1e-3)
    assert float(rows[-1].group(3)) == pytest.approx(raw["modes"][-1]["end"], abs=1e-3)

    lines = check_fits(run(["inspect", "flicker.parquet", "--min-run", "0", "--max-rows", "10000"], 80, logs), 80)
    rows = [m for m in map(MODE_ROW.match, lines) if m]
    assert [m.group(1) for m in rows] == [m["mode"] for m in raw["modes"]]


def _rows(*spec) -> list[TimelineRow]:
    out, t = [], 0.0
    for mode, time in spec:
        out.append(TimelineRow(mode, t, t + time - 0.002, time))
        t += time
    return out


def test_merge_short_runs_collapses_flicker_into_the_longer_stretch():
    flicker = _rows(("1", 4.0), ("2s", 0.1), ("1", 0.05), ("2s", 0.2), ("1", 0.3), ("2s", 0.06), ("1", 3.0),
                    ("4", 2.0), ("1", 0.1), ("4", 1.0))
    merged = merge_short_runs(flicker, 0.5)
    assert [(r.mode, r.runs) for r in merged] == [("1", 7), ("4", 3)]
    assert sum(r.time for r in merged) == pytest.approx(sum(r.time for r in flicker))
    assert sum(r.runs for r in merged) == len(flicker)
    assert merged[0].t_start == flicker[0].t_start and merged[-1].t_end == flicker[-1].t_end
    assert all(a.t_end < b.t_start for a, b in zip(merged, merged[1:]))
    assert merge_short_runs(flicker, 0) == tuple(flicker)


def test_merge_short_runs_between_different_modes():
    # a short cluster between 1 and 4 goes to the mode with more time inside it
    rows = merge_short_runs(_rows(("1", 2.0), ("2s", 0.1), ("1", 0.15), ("2s", 0.1), ("4", 2.0)), 0.5)
    assert [(r.mode, r.runs) for r in rows] == [("1", 4), ("4", 1)]
    rows = merge_short_runs(_rows(("1", 2.0), ("2s", 0.1), ("4", 0.2), ("2s", 0.1), ("4", 2.0)), 0.5)
    assert [(r.mode, r.runs) for r in rows] == [("1", 1), ("4", 4)]
    # a long stretch of flicker between different modes is a merged row of its own, named by its longest mode
    rows = merge_short_runs(_rows(("1", 2.0), ("2s", 0.3), ("1", 0.1), ("2s", 0.3), ("4", 2.0)), 0.5)
    assert [(r.mode, r.runs) for r in rows] == [("1", 1), ("2s", 3), ("4", 1)]
    assert rows[1].time == pytest.approx(0.7)
    # only short runs: one row
    rows = merge_short_runs(_rows(("1", 0.1), ("2s", 0.25), ("1", 0.1)), 0.5)
    assert [(r.mode, r.runs) for r in rows] == [("2s", 3)]
    with pytest.raises(ValueError, match="min_run"):
        merge_short_runs(rows, -1)


def test_merge_short_runs_on_a_flickering_log(logs):
    log = read_log(logs / "flicker.parquet")
    check = preflight([log], PROTOTYPE).files[0]
    every = check.mode_rows(0)
    assert len(every) == check.summary.n_detected_runs > 40
    merged = check.mode_rows(0.5)
    assert len(merged) < 20 and sum(r.runs for r in merged) == len(every)
    assert sum(r.time for r in merged) == pytest.approx(log.n_samples * log.sample_time)
    assert all(r.runs > 1 or r.time >= 0.5 for r in merged)
    assert sum(r.time for r in check.timeline_rows(0.5)) == pytest.approx(sum(r.time for r in check.row_runs))


def test_batch_table_fits(logs, tmp_path):
    pytest.importorskip("distributed")
    manifest = {"jobs": [
        {"name": "agv-with-a-rather-long-name-07", "logs": [str(logs / "ident.parquet")]},
        {"name": "missing", "logs": [str(logs / "a" / "folder" / "that" / "is" / "not" / "there" / "ident.parquet")]},
    ]}
    (tmp_path / "fleet.yaml").write_text(yaml.safe_dump(manifest), encoding="utf-8")
    text = run(["batch", "fleet.yaml", "--out", "r.parquet", "--workers", "1"], 80, tmp_path)
    lines = check_fits(text, 80)
    table = pd.read_parquet(tmp_path / "r.parquet")
    job = table[table["job"] == "agv-with-a-rather-long-name-07"].iloc[0]
    row = [line for line in lines if line.startswith("agv-with-a-rather-long-name-07")]
    assert len(row) == 1 and f"{int(job['rows']):,}" in row[0] and f"{job['cond']:.4g}" in row[0], text
    error = table[table["job"] == "missing"]["error"].iloc[0].splitlines()[0]
    # the error in full: wrapped between words, and a word longer than the line (a path) folded
    assert "".join(error.split()) in "".join(text.split())
