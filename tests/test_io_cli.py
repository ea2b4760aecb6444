"""``agvdyn convert`` and ``agvdyn inspect`` end to end, through the typer app."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from agvdyn.cli import app
from agvdyn.io import read_log, write_bag, write_log, Log, read_mapping
from agvdyn.kinematics import Mode, nominal_steering
from agvdyn.platform import PROTOTYPE, Geometry, write_platform

MAPPINGS = Path(__file__).resolve().parents[1] / "examples" / "mappings"
runner = CliRunner()


def mode_log(dt: float = 0.002) -> pd.DataFrame:
    """1 s straight, 1 s aligning the wheels at rest, 1 s pure rotation."""
    t = np.arange(int(3.0 / dt)) * dt
    rot = nominal_steering(PROTOTYPE, Mode.ROTATION)
    ramp = np.clip(t - 1.0, 0.0, 1.0)[:, None]  # 0 before 1 s, 1 after 2 s
    alpha = ramp * rot[None, :]
    data = {"t": t, "alpha_l": alpha[:, 0], "alpha_r": alpha[:, 1]}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"beta_{w}"] = 0.5 * t + k
        data[f"m_{w}"] = np.sin(t + k)
    frame = pd.DataFrame(data)
    frame["segment"] = np.where(t < 1.0, "straight", np.where(t < 2.0, "align", "rotation"))
    return frame


def test_inspect_reports_segments_and_modes(tmp_path):
    path = write_log(tmp_path / "run.parquet", mode_log())
    result = runner.invoke(app, ["inspect", str(path), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    assert info["samples"] == 1500
    assert info["rate"] == pytest.approx(500.0)
    assert info["duration"] == pytest.approx(2.998)
    assert [(s["name"], s["start"]) for s in info["segments"]] == [("straight", 0.0), ("align", 1.0), ("rotation", 2.0)]
    modes = [(m["mode"], m["start"], m["end"]) for m in info["modes"]]
    assert [m[0] for m in modes] == ["2s", "1", "4"]
    # Mode changes where |alpha - nominal| crosses the 0.02 rad tolerance on the ramp.
    rot = float(np.max(np.abs(nominal_steering(PROTOTYPE, Mode.ROTATION))))
    assert modes[1][1] == pytest.approx(1.0 + 0.02 / rot, abs=0.003)
    assert modes[2][1] == pytest.approx(2.0 - 0.02 / rot, abs=0.003)
    text = runner.invoke(app, ["inspect", str(path)])
    assert text.exit_code == 0
    assert "straight" in text.output and "4 rotation" in text.output and "500 Hz" in text.output


def test_convert_bag_then_inspect(tmp_path):
    mapping = MAPPINGS / "ros2_control.yaml"
    log = Log.from_frame(mode_log())
    bag = write_bag(log, tmp_path / "bag", read_mapping(mapping), "mcap", platform=PROTOTYPE)
    out = tmp_path / "run.parquet"
    write_platform(tmp_path / "proto.yaml", PROTOTYPE)
    result = runner.invoke(app, ["convert", str(bag), "--mapping", str(mapping), "--out", str(out), "--platform", str(tmp_path / "proto.yaml")])
    assert result.exit_code == 0, result.output
    assert "resampled at 500 Hz" in result.output and "i_G = 25" in result.output
    back = read_log(out)
    np.testing.assert_allclose(back.alpha, log.alpha, atol=1e-12)
    assert back.sidecar["conversion"]["input"] == "ros2_bag"
    assert back.sidecar["conversion"]["i_G"] == PROTOTYPE.i_G
    assert back.sidecar["platform"]["i_G"] == PROTOTYPE.i_G
    result = runner.invoke(app, ["inspect", str(bag), "--mapping", str(mapping), "--json"])
    assert result.exit_code == 2 and "need the gear ratio i_G" in result.output  # no platform, no i_G: refused
    write_platform(tmp_path / "proto.yaml", PROTOTYPE)
    result = runner.invoke(app, ["inspect", str(bag), "--mapping", str(mapping), "--json",
                                 "--platform", str(tmp_path / "proto.yaml")])
    assert result.exit_code == 0, result.output
    assert [m["mode"] for m in json.loads(result.output)["modes"]] == ["2s", "1", "4"]


def test_errors_are_clean_with_exit_code_2(tmp_path):
    frame = mode_log()
    frame.loc[10, "t"] = frame.loc[9, "t"]
    bad = tmp_path / "bad.csv"
    frame.to_csv(bad, index=False)
    for args in (["inspect", str(bad)], ["convert", str(bad), "--out", str(tmp_path / "x.parquet")]):
        result = runner.invoke(app, args)
        assert result.exit_code == 2
        assert "error:" in result.output and "duplicated time" in result.output
        assert "Traceback" not in result.output
    assert not (tmp_path / "x.parquet").exists()
    result = runner.invoke(app, ["inspect", str(tmp_path / "nothing.parquet")])
    assert result.exit_code == 2 and "no such file" in result.output
    (tmp_path / "m.yaml").write_text("input: table\nsignals: {}\nfoo: 1\n")
    result = runner.invoke(app, ["convert", str(bad), "--mapping", str(tmp_path / "m.yaml"), "--out", str(tmp_path / "y.csv")])
    assert result.exit_code == 2 and "foo: unknown key" in result.output


def test_convert_refuses_to_overwrite_its_input(tmp_path):
    path = write_log(tmp_path / "run.csv", mode_log())
    before = path.read_bytes()
    result = runner.invoke(app, ["convert", str(path), "--out", str(path)])
    assert result.exit_code == 2 and "overwrite the input" in result.output
    assert path.read_bytes() == before


def test_inspect_uses_the_platform_of_the_sidecar(tmp_path):
    square = Geometry(l=1.0, b=1.0, a=0.05, r=0.1, i_G=20.0, name="square")
    frame = mode_log()
    rot = nominal_steering(square, Mode.ROTATION)  # +-45 degrees, not the prototype's +-56.3
    late = frame["t"].to_numpy() >= 2.0
    frame.loc[late, "alpha_l"], frame.loc[late, "alpha_r"] = rot[0], rot[1]
    frame.loc[(frame["t"] > 1.0) & ~late, ["alpha_l", "alpha_r"]] = 0.3 * rot  # somewhere in between
    path = write_log(tmp_path / "sq.parquet", frame, {"platform": square.to_dict()})
    info = json.loads(runner.invoke(app, ["inspect", str(path), "--json"]).output)
    assert info["platform"]["name"] == "square"
    assert info["modes"][-1]["mode"] == "4"
    write_platform(tmp_path / "proto.yaml", PROTOTYPE)
    info = json.loads(runner.invoke(app, ["inspect", str(path), "--json", "--platform", str(tmp_path / "proto.yaml")]).output)
    assert info["modes"][-1]["mode"] != "4"


def test_short_mode_runs_are_merged_only_in_the_listing(tmp_path):
    frame = mode_log()
    blips = [100, 101, 300]  # single rows leaving the straight configuration (noise)
    frame.loc[blips, "alpha_l"] = 0.1
    path = write_log(tmp_path / "blips.parquet", frame)
    raw = json.loads(runner.invoke(app, ["inspect", str(path), "--json", "--min-duration", "0"]).output)
    merged = json.loads(runner.invoke(app, ["inspect", str(path), "--json"]).output)
    assert [m["mode"] for m in raw["modes"]] == ["2s", "1", "2s", "1", "2s", "1", "4"]
    assert [m["mode"] for m in merged["modes"]] == ["2s", "1", "4"]
    assert merged["detected_runs"] == 7
    assert merged["mode_time"] == raw["mode_time"]  # totals from the detection, not the merged list
    assert raw["mode_time"]["1"] == pytest.approx(merged["modes"][1]["duration"] + 0.002 + 3 * 0.002, abs=1e-9)


def test_convert_needs_a_gear_ratio_and_says_how_to_give_it(tmp_path):
    mapping = MAPPINGS / "ros2_control.yaml"  # wheel-side torques
    bag = write_bag(Log.from_frame(mode_log()), tmp_path / "bag", read_mapping(mapping), "mcap", platform=PROTOTYPE)
    out = tmp_path / "run.parquet"
    result = runner.invoke(app, ["convert", str(bag), "--mapping", str(mapping), "--out", str(out)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "m_fl ('front_left_wheel_joint', side: wheel)" in result.output
    assert "--platform FILE" in result.output and "i_G: <ratio>" in result.output
    assert not out.exists()
    # i_G in the mapping: no platform needed; recorded in the sidecar, no platform invented.
    with_ratio = tmp_path / "with_ratio.yaml"
    with_ratio.write_text(mapping.read_text() + "i_G: 25\n")
    result = runner.invoke(app, ["convert", str(bag), "--mapping", str(with_ratio), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "gear ratio i_G = 25 (from the mapping)" in result.output
    back = read_log(out)
    assert back.sidecar["conversion"]["i_G"] == 25 and "platform" not in back.sidecar
    # Both, disagreeing: an error naming both values.
    write_platform(tmp_path / "ten.yaml", Geometry(l=1.2, b=0.8, a=0.05, r=0.1, i_G=10.0, name="ten"))
    result = runner.invoke(app, ["convert", str(bag), "--mapping", str(with_ratio), "--out", str(tmp_path / "x.parquet"),
                                 "--platform", str(tmp_path / "ten.yaml")])
    assert result.exit_code == 2 and "i_G: 25 but the platform ten has i_G = 10" in result.output
    # Our own schema needs no gear ratio.
    ours = write_log(tmp_path / "ours.csv", mode_log())
    result = runner.invoke(app, ["convert", str(ours), "--out", str(tmp_path / "ours.parquet")])
    assert result.exit_code == 0, result.output


def test_convert_clips_within_the_stop_tolerance_and_reports_gaps(tmp_path):
    frame = mode_log()
    frame.loc[[10, 11], "alpha_l"] = np.pi / 2 + 0.004
    frame.loc[1000:, "t"] += 0.1  # a dropout
    path = write_log(tmp_path / "raw.csv", frame)
    before = path.read_bytes()
    out = tmp_path / "clean.parquet"
    result = runner.invoke(app, ["convert", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert path.read_bytes() == before
    assert "clipped to the steering stops" in result.output and "2 rows of alpha_l" in result.output
    assert "1 time gap(s)" in result.output and "2 continuous stretches" in result.output
    back = read_log(out)
    assert back.sidecar["clipped_to_stops"] == {"alpha_l": 2, "alpha_r": 0}
    assert back.alpha[:, 0].max() == np.pi / 2 and len(back.stretches()) == 2
    result = runner.invoke(app, ["convert", str(path), "--out", str(tmp_path / "y.parquet"), "--stop-tolerance", "0.001"])
    assert result.exit_code == 2 and "stop tolerance 0.001 rad" in result.output and "--stop-tolerance" in result.output
