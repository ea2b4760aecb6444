"""Our log schema: round trips and one test per kind of bad input."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvdyn.io import (
    LOG_COLUMNS,
    SEGMENTS,
    STRETCH_GAP_SAMPLES,
    Log,
    LogError,
    check_frame,
    read_log,
    sidecar_path,
    write_log,
)


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


def test_gap_longer_than_allowed_when_limited(tmp_path):
    """Gaps are read by default; a caller that sets max_gap_samples still gets them refused."""
    frame = make_frame()
    frame.loc[120:, "t"] += 0.002 * 5  # a gap of 6 sample periods
    path = write_csv(tmp_path, frame)
    assert read_log(path).n_samples == 200
    with pytest.raises(LogError, match=r"column 't', row 120 .*gap of 0\.012 s \(6\.0 sample periods\) from t = 0\.238 s to t = 0\.25 s"):
        read_log(path, max_gap_samples=5)
    assert read_log(path, max_gap_samples=6.5).n_samples == 200


def test_steering_beyond_the_stop_tolerance(tmp_path):
    frame = make_frame()
    frame.loc[70, "alpha_r"] = math.pi / 2 + 0.0224
    path = write_csv(tmp_path, frame)
    with pytest.raises(LogError) as err:
        read_log(path)
    text = str(err.value)
    assert "bad.csv: column 'alpha_r', row 70 (line 72 of the file) (t = 0.14 s): steering angle 1.5932 rad" in text
    assert "beyond the mechanical stop +1.5708 rad (pi/2) by 0.0224 rad" in text
    assert "stop tolerance 0.01 rad" in text and "stop_tolerance=" in text and "--stop-tolerance" in text
    assert "np.float64" not in text
    log = read_log(path, stop_tolerance=0.03)  # raised: clipped instead
    assert log.clipped == {"alpha_l": 0, "alpha_r": 1} and log.alpha[70, 1] == math.pi / 2
    frame.loc[70, "alpha_r"] = -math.pi / 2 - 0.02
    with pytest.raises(LogError, match=r"row 70 .*steering angle -1\.5908 rad is beyond the mechanical stop -1\.5708 rad \(pi/2\) by 0\.02 rad"):
        read_log(write_csv(tmp_path, frame))


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_steering_within_the_stop_tolerance_is_clipped_and_counted(tmp_path, suffix):
    frame = make_frame()
    over = {"alpha_l": [(10, math.pi / 2 + 0.004), (11, math.pi / 2 + 0.01)], "alpha_r": [(50, -math.pi / 2 - 0.003)]}
    for col, rows in over.items():
        for row, value in rows:
            frame.loc[row, col] = value
    frame.loc[12, "alpha_l"] = math.pi / 2  # at the stop: not clipped
    path = write_log(tmp_path / f"run{suffix}", frame)  # written as measured, not clipped
    written = write_log(tmp_path / f"copy{suffix}", frame)
    before = path.read_bytes()
    log = read_log(path)
    assert path.read_bytes() == before  # the input file is never modified
    assert log.clipped == {"alpha_l": 2, "alpha_r": 1}
    assert log.alpha[10, 0] == math.pi / 2 and log.alpha[11, 0] == math.pi / 2 and log.alpha[50, 1] == -math.pi / 2
    assert np.abs(log.alpha).max() == math.pi / 2
    others = np.ones(len(frame), dtype=bool)
    others[[10, 11, 50]] = False
    np.testing.assert_array_equal(log.alpha[others], frame[["alpha_l", "alpha_r"]].to_numpy()[others])
    assert read_log(written).clipped == {"alpha_l": 2, "alpha_r": 1}
    # In memory alike; the input frame keeps its values; a log without clipping counts zeros.
    mem = Log.from_frame(frame)
    assert mem.clipped == {"alpha_l": 2, "alpha_r": 1} and frame.loc[10, "alpha_l"] == math.pi / 2 + 0.004
    assert dataclasses.replace(mem, sidecar={"x": 1}).clipped == mem.clipped  # a field: it survives copies
    assert Log.from_frame(make_frame()).clipped == {"alpha_l": 0, "alpha_r": 0}
    assert check_frame(frame)["alpha_l"].max() == math.pi / 2


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
    dt=st.floats(1e-4, 0.07),
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


# --- real logs: dropouts, time in milliseconds, number formatting ---------------------------

@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_log_with_a_dropout_is_read_and_split_into_stretches(tmp_path, suffix):
    frame = make_frame(n=1000)
    frame.loc[600:, "t"] += 0.1  # 0.1 s missing at 500 Hz
    path = write_log(tmp_path / f"drop{suffix}", frame)
    log = read_log(path)
    assert log.n_samples == 1000 and log.sample_time == pytest.approx(0.002)
    assert STRETCH_GAP_SAMPLES == 3.0
    assert log.stretches() == (slice(0, 600), slice(600, 1000))
    (gap,) = log.gaps()
    assert gap == pytest.approx((599 * 0.002, 600 * 0.002 + 0.1))
    # A step of 3 nominal steps is still continuous; a longer one is a cut; the threshold is settable.
    frame = make_frame(n=100)
    frame.loc[30:, "t"] += 2 * 0.002  # a step of 3 periods
    frame.loc[70:, "t"] += 3 * 0.002  # a step of 4 periods
    log = Log.from_frame(frame)
    assert log.stretches() == (slice(0, 70), slice(70, 100))
    assert log.stretches(2.5) == (slice(0, 30), slice(30, 70), slice(70, 100))
    assert log.stretches(5) == (slice(0, 100),) and log.gaps(5) == ()
    with pytest.raises(ValueError, match="max_step_samples"):
        log.stretches(0.5)


def test_non_increasing_time_stays_an_error_with_plain_numbers(tmp_path):
    frame = make_frame()
    frame.loc[60, "t"] = frame.loc[59, "t"] - 0.001
    with pytest.raises(LogError) as err:
        read_log(write_csv(tmp_path, frame))
    assert "decreasing time t = 0.117 after t = 0.118" in str(err.value)
    assert "np.float64" not in str(err.value)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_time_in_milliseconds_is_named(tmp_path, suffix):
    frame = make_frame()
    frame["t"] = frame["t"] * 1e3  # 0, 2, 4, ... ms
    path = tmp_path / f"ms{suffix}"
    frame.to_csv(path, index=False) if suffix == ".csv" else frame.to_parquet(path)
    with pytest.raises(LogError) as err:
        read_log(path)
    text = str(err.value)
    assert f"ms{suffix}: column 't'" in text
    assert "looks like it is in milliseconds" in text and "nominal time step 2 " in text
    assert "convert 't' to seconds" in text and "time: {column: t, unit: ms}" in text
    assert "np.float64" not in text


def test_a_step_putting_the_filter_above_nyquist_is_refused():
    frame = make_frame(n=50, dt=0.1, segments=False)  # 10 Hz: Nyquist pi/dt = 31.4 rad/s < 40 rad/s
    with pytest.raises(LogError, match=r"nominal time step 0\.1 s \(10 Hz\) is too long: the 40 rad/s filter cut-off .*milliseconds"):
        Log.from_frame(frame)
    Log.from_frame(make_frame(n=50, dt=0.07, segments=False))
    check_frame(frame, max_sample_time=0.2)  # settable


def test_a_rewritten_parquet_log_is_read_anew_not_from_the_kept_footer(tmp_path):
    from agvdyn.io.chunks import log_rows_count

    path = write_log(tmp_path / "a.parquet", make_frame(n=300))
    assert log_rows_count(path) == 300 and read_log(path).t.size == 300  # footer read once, kept
    write_log(path, make_frame(n=120))  # another size: another file version
    assert log_rows_count(path) == 120
    assert read_log(path).t.size == 120


def test_parquet_read_without_pandas_equals_pandas_over_row_groups_and_missing_labels(tmp_path):
    """Our Parquet columns come from pyarrow's buffers (no pandas import): the same values and
    segment labels as pandas reads, over several row groups and with missing labels."""
    import subprocess
    import sys

    import pyarrow as pa
    import pyarrow.parquet as pq

    frame = make_frame(n=1000)
    labels = np.array(frame["segment"].astype(object).to_numpy(), dtype=object)
    labels[::7] = None
    frame["segment"] = pd.Categorical(labels, categories=list(SEGMENTS))
    path = tmp_path / "groups.parquet"
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, row_group_size=300)
    log = read_log(path)
    want = pd.read_parquet(path)
    for col in LOG_COLUMNS:
        assert np.array_equal(log.frame[col].to_numpy(), want[col].to_numpy())
    got_labels = log.frame["segment"].astype(object).where(log.frame["segment"].notna(), None)
    assert list(got_labels) == list(want["segment"].astype(object).where(want["segment"].notna(), None))
    probe = f"import sys\nfrom agvdyn.io import read_log\nread_log({str(path)!r})\nprint('pandas' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_our_parquet_log_has_required_float_columns_and_reads_back_as_written(tmp_path):
    """write_log stores the float columns as required (no definition levels to decode) and keeps
    pandas' metadata: pandas and read_log give back the checked frame; a nullable file of the same
    values (another writer's) reads the same."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    frame = make_frame(n=400)
    path = write_log(tmp_path / "req.parquet", frame)
    schema = pq.read_schema(path)
    assert all(not schema.field(c).nullable for c in LOG_COLUMNS)
    assert pa.types.is_dictionary(schema.field("segment").type)
    back = pd.read_parquet(path)
    assert isinstance(back["segment"].dtype, pd.CategoricalDtype)
    nullable = tmp_path / "nullable.parquet"
    pq.write_table(pa.Table.from_pandas(back, preserve_index=False), nullable)
    assert pq.read_schema(nullable).field("t").nullable
    for p in (path, nullable):
        log = read_log(p)
        for col in LOG_COLUMNS:
            assert np.array_equal(log.frame[col].to_numpy(), frame[col].to_numpy())
        assert list(log.frame["segment"].astype(object)) == list(frame["segment"].astype(object))
