"""Our log schema: round trips and one test per kind of bad input."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.io import LOG_COLUMNS, SEGMENTS, Log, LogError, check_frame, read_log, sidecar_path, write_log


def make_frame(n: int = 200, dt: float = 0.002, segments: bool = True) -> pd.DataFrame:
    t = np.arange(n) * dt
    rng = np.random.default_rng(0)
    data = {"t": t, "alpha_l": 0.4 * np.sin(t), "alpha_r": -0.3 * np.sin(2 * t)}
    for w in ("fl", "rl", "fr", "rr"):
        data[f"beta_{w}"] = 3.0 * t + rng.normal(size=n) * 1e-3
        data[f"m_{w}"] = rng.normal(size=n)
    frame = pd.DataFrame(data)
    if segments:
        names = np.array(["steer_left"] * (n // 2) + ["rotation"] * (n - n // 2), dtype=object)
        frame["segment"] = names
    return frame


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_round_trip_is_exact(tmp_path, suffix):
    frame = make_frame()
    frame["extra"] = np.arange(len(frame)) * 0.5
    side = {"platform": {"l": 1.2, "b": 0.8}, "true": {"C_l": np.float64(0.3342)}, "notes": ("a", "b")}
    path = write_log(tmp_path / f"run{suffix}", frame, side)
    assert sidecar_path(path).name == f"run{suffix}.yaml"
    log = read_log(path)
    for col in LOG_COLUMNS:
        np.testing.assert_array_equal(log.frame[col].to_numpy(), frame[col].to_numpy())
        assert log.frame[col].dtype == np.float64
    np.testing.assert_array_equal(log.segments, frame["segment"].to_numpy().astype(str))
    np.testing.assert_array_equal(log.frame["extra"].to_numpy(), frame["extra"].to_numpy())
    assert log.sidecar == {"platform": {"l": 1.2, "b": 0.8}, "true": {"C_l": 0.3342}, "notes": ["a", "b"]}
    assert log.alpha.shape == (200, 2) and log.beta.shape == (200, 4) and log.torque.shape == (200, 4)
    np.testing.assert_array_equal(log.alpha[:, 1], frame["alpha_r"].to_numpy())
    np.testing.assert_array_equal(log.torque[:, 3], frame["m_rr"].to_numpy())
    assert log.sample_time == pytest.approx(0.002)
    assert log.duration == pytest.approx(199 * 0.002)
    runs = log.segment_runs()
    assert [(r.name, r.start, r.stop) for r in runs] == [("steer_left", 0, 100), ("rotation", 100, 200)]
    assert log.segment_slices() == {"steer_left": [slice(0, 100)], "rotation": [slice(100, 200)]}


def test_log_without_segment_and_without_sidecar(tmp_path):
    path = write_log(tmp_path / "a.parquet", make_frame(segments=False))
    log = read_log(path)
    assert log.segments is None and log.segment_runs() == () and log.sidecar == {}


def test_writing_without_sidecar_removes_a_stale_one(tmp_path):
    path = write_log(tmp_path / "a.parquet", make_frame(), {"old": 1})
    assert sidecar_path(path).exists()
    write_log(path, make_frame())
    assert not sidecar_path(path).exists()


def test_empty_segment_means_no_segment(tmp_path):
    frame = make_frame()
    frame.loc[90:109, "segment"] = None
    log = read_log(write_log(tmp_path / "a.csv", frame))
    assert log.segments[95] == ""
    assert [(r.name, r.start, r.stop) for r in log.segment_runs()] == [("steer_left", 0, 90), ("rotation", 110, 200)]


def test_read_never_modifies_the_file(tmp_path):
    path = write_log(tmp_path / "a.csv", make_frame())
    before = path.read_bytes()
    read_log(path)
    assert path.read_bytes() == before


def test_arrays_are_read_only(tmp_path):
    log = read_log(write_log(tmp_path / "a.parquet", make_frame()))
    with pytest.raises(ValueError):
        log.alpha[0, 0] = 1.0


def test_segments_list_contains_the_identification_sequence():
    assert {"steer_left", "steer_right", "straight", "rotation", "lateral", "lane_change", "align"} <= set(SEGMENTS)


# --- one test per kind of error, each checking that file, column and row are named ----------

def write_csv(tmp_path, frame) -> str:
    path = tmp_path / "bad.csv"
    frame.to_csv(path, index=False)
    return path


def test_missing_column(tmp_path):
    path = write_csv(tmp_path, make_frame().drop(columns=["m_rl"]))
    with pytest.raises(LogError, match=r"bad\.csv: missing columns \['m_rl'\]"):
        read_log(path)


def test_non_numeric_value(tmp_path):
    frame = make_frame().astype({"beta_fr": object})
    frame.loc[17, "beta_fr"] = "abc"
    with pytest.raises(LogError, match=r"bad\.csv: column 'beta_fr', row 17 \(line 19 of the file\): value 'abc' is not a number"):
        read_log(write_csv(tmp_path, frame))


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_value(tmp_path, value):
    frame = make_frame()
    frame.loc[33, "m_fl"] = value
    with pytest.raises(LogError, match=r"column 'm_fl', row 33 .*not finite"):
        read_log(write_csv(tmp_path, frame))


def test_duplicated_time(tmp_path):
    frame = make_frame()
    frame.loc[50, "t"] = frame.loc[49, "t"]
    with pytest.raises(LogError, match=r"column 't', row 50 .*duplicated time"):
        read_log(write_csv(tmp_path, frame))


def test_decreasing_time(tmp_path):
    frame = make_frame()
    frame.loc[60, "t"] = frame.loc[59, "t"] - 0.001
    with pytest.raises(LogError, match=r"column 't', row 60 .*decreasing time"):
        read_log(write_csv(tmp_path, frame))


def test_gap_longer_than_allowed(tmp_path):
    frame = make_frame()
    frame.loc[120:, "t"] += 0.002 * 5  # a gap of 6 sample periods
    path = write_csv(tmp_path, frame)
    with pytest.raises(LogError, match=r"column 't', row 120 .*gap of 0\.012 s \(6\.0 sample periods\)"):
        read_log(path)
    assert read_log(path, max_gap_samples=6.5).n_samples == 200


def test_steering_beyond_range(tmp_path):
    frame = make_frame()
    frame.loc[70, "alpha_r"] = math.pi / 2 + 1e-3
    with pytest.raises(LogError, match=r"column 'alpha_r', row 70 .*beyond the mechanical range"):
        read_log(write_csv(tmp_path, frame))
    frame.loc[70, "alpha_r"] = math.pi / 2 + 1e-7  # within the tolerance
    read_log(write_csv(tmp_path, frame))


def test_steering_in_degrees_is_caught(tmp_path):
    frame = make_frame()
    frame["alpha_l"] = np.degrees(frame["alpha_l"]) + 5.0
    with pytest.raises(LogError, match=r"column 'alpha_l', row 0 .*expected radians"):
        read_log(write_csv(tmp_path, frame))


def test_unknown_segment(tmp_path):
    frame = make_frame()
    frame.loc[150, "segment"] = "sidewards"
    with pytest.raises(LogError, match=r"column 'segment', row 150 .*unknown segment name 'sidewards'"):
        read_log(write_csv(tmp_path, frame))


def test_unknown_suffix_and_missing_file(tmp_path):
    with pytest.raises(LogError, match="unknown log format"):
        read_log(tmp_path / "a.txt")
    with pytest.raises(LogError, match="no such file"):
        read_log(tmp_path / "a.parquet")


def test_write_log_checks_the_frame(tmp_path):
    frame = make_frame()
    frame.loc[5, "t"] = 10.0
    with pytest.raises(LogError, match=r"out\.parquet: column 't'"):
        write_log(tmp_path / "out.parquet", frame)
    assert not (tmp_path / "out.parquet").exists()


def test_check_frame_does_not_modify_its_input():
    frame = make_frame()
    copy = frame.copy()
    check_frame(frame)
    pd.testing.assert_frame_equal(frame, copy)


@settings(max_examples=25, deadline=None)
@given(
    n=st.integers(2, 50),
    dt=st.floats(1e-4, 0.1),
    angles=st.lists(st.floats(-math.pi / 2, math.pi / 2), min_size=2, max_size=2),
)
def test_from_frame_accepts_any_valid_uniform_log(n, dt, angles):
    t = np.arange(n) * dt
    data = {c: np.zeros(n) for c in LOG_COLUMNS}
    data["t"] = t
    data["alpha_l"][:] = angles[0]
    data["alpha_r"][:] = angles[1]
    log = Log.from_frame(pd.DataFrame(data))
    assert log.sample_time == pytest.approx(dt)
    assert log.duration == pytest.approx((n - 1) * dt)


def test_unknown_segment_in_a_categorical_parquet_column(tmp_path):
    frame = make_frame()
    frame.loc[150, "segment"] = "sidewards"
    frame["segment"] = frame["segment"].astype("category")
    frame.to_parquet(tmp_path / "bad.parquet")
    with pytest.raises(LogError, match=r"bad\.parquet: column 'segment', row 150 .*unknown segment name 'sidewards'"):
        read_log(tmp_path / "bad.parquet")
    frame.loc[150, "segment"] = None
    log = read_log_from(frame, tmp_path)
    assert log.segments[150] == "" and log.segments[149] == "rotation"


def read_log_from(frame, tmp_path):
    frame.to_parquet(tmp_path / "ok.parquet")
    return read_log(tmp_path / "ok.parquet")
