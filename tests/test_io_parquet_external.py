"""Parquet logs written by other tools with our column names (issue 28) are read straight into numpy,
without pandas, and give the same log as the pandas path: float32 and integer columns, a ``segment``
column of plain strings (empty, missing, padded, in several row groups) or categorical."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from agvdyn.io import Log, LogError, read_log
from agvdyn.io.log import LOG_COLUMNS, _check, read_table
from agvdyn.io.schema import LazyFrame


def _frame(n: int = 3000, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.002
    data = {"t": t, "alpha_l": 0.5 * np.sin(0.3 * t), "alpha_r": 0.4 * np.sin(0.2 * t)}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"beta_{w}"] = 3.0 * t + k
        data[f"m_{w}"] = rng.normal(size=n)
    frame = pd.DataFrame(data)
    names = np.array(["steer_left", " steer_right ", "", None, "straight", "rotation"], dtype=object)
    frame["segment"] = names[np.minimum(np.arange(n) * len(names) // n, len(names) - 1)]
    return frame


def _pandas_log(path: Path) -> Log:
    checked, clipped = _check(read_table(path), path, max_gap_samples=np.inf, stop_tolerance=0.01)
    return Log(path, checked, {}, clipped)


def _assert_same(path: Path) -> None:
    fast, ref = read_log(path), _pandas_log(path)
    assert type(object.__getattribute__(fast, "frame")) is LazyFrame  # the numpy path was taken
    for name in ("t", "alpha", "beta", "torque", "segments"):
        a, b = getattr(fast, name), getattr(ref, name)
        assert (a is None and b is None) or (a.dtype == b.dtype and np.array_equal(a, b)), name
    assert fast.sample_time == ref.sample_time and fast.clipped == ref.clipped
    pd.testing.assert_frame_equal(fast.frame, ref.frame)


@pytest.mark.parametrize("torques", ["float32", "int32", "float64"])
def test_pandas_written_parquet_reads_as_through_pandas(tmp_path, torques):
    frame = _frame()
    for col in ("m_fl", "m_rl", "m_fr", "m_rr"):
        frame[col] = (frame[col] * 100).astype(torques)
    frame.to_parquet(tmp_path / "log.parquet")
    _assert_same(tmp_path / "log.parquet")


def test_string_segments_in_several_row_groups_and_large_strings(tmp_path):
    table = pa.Table.from_pandas(_frame(), preserve_index=False)
    pq.write_table(table, tmp_path / "groups.parquet", row_group_size=700)
    _assert_same(tmp_path / "groups.parquet")
    large = table.set_column(table.schema.get_field_index("segment"), "segment",
                             table.column("segment").cast(pa.large_string()))
    pq.write_table(large, tmp_path / "large.parquet", row_group_size=1000)
    _assert_same(tmp_path / "large.parquet")


def test_categorical_and_no_segment(tmp_path):
    frame = _frame()
    frame["segment"] = frame["segment"].astype("category")
    frame.to_parquet(tmp_path / "cat.parquet")
    _assert_same(tmp_path / "cat.parquet")
    frame.drop(columns="segment").to_parquet(tmp_path / "none.parquet")
    _assert_same(tmp_path / "none.parquet")
    assert read_log(tmp_path / "none.parquet").segments is None


def test_unknown_segment_name_is_the_same_error(tmp_path):
    frame = _frame()
    frame.loc[2500, "segment"] = "  parking lot "
    frame.to_parquet(tmp_path / "bad.parquet")
    with pytest.raises(LogError) as fast:
        read_log(tmp_path / "bad.parquet")
    with pytest.raises(LogError) as ref:
        _pandas_log(tmp_path / "bad.parquet")
    assert str(fast.value) == str(ref.value)
    assert "row 2500" in str(fast.value) and "'parking lot'" in str(fast.value)


def test_other_layouts_still_go_through_pandas(tmp_path):
    frame = _frame()
    frame["extra"] = 1.0
    frame.to_parquet(tmp_path / "extra.parquet")
    log = read_log(tmp_path / "extra.parquet")
    assert "extra" in log.frame.columns  # extra columns are kept, as before
    frame = _frame().drop(columns="segment")
    frame["m_fl"] = frame["m_fl"] > 0
    frame.to_parquet(tmp_path / "bool.parquet")
    with pytest.raises(LogError, match="booleans"):
        read_log(tmp_path / "bool.parquet")


def test_reading_a_pandas_written_log_imports_no_pandas(tmp_path):
    frame = _frame()
    frame["m_fl"] = frame["m_fl"].astype("float32")
    frame.to_parquet(tmp_path / "log.parquet")
    code = (f"import sys\nfrom agvdyn.io import read_log\nlog = read_log({str(tmp_path / 'log.parquet')!r})\n"
            "log.t, log.alpha, log.torque, log.segment_runs()\nprint('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "False"
    assert len(LOG_COLUMNS) == 11


def test_the_joint_state_types_of_the_reader_are_ros2_humbles():
    from rosbags.typesys import Stores, get_typestore

    from agvdyn.io.bag import _JOINT_STATE_TYPES, _joint_state_typestore

    small, full = _joint_state_typestore(), get_typestore(Stores.ROS2_HUMBLE)
    for name in _JOINT_STATE_TYPES:
        assert small.fielddefs[name] == full.fielddefs[name]
