"""A log written from numpy columns (``write_log(path, {column: array})``, what ``agvdyn simulate``
writes, without pandas: issue 28) is the file the same DataFrame gives, byte for byte, and its
checks are the DataFrame's."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from agvdyn.io import LOG_COLUMNS, LogError, read_log, write_log
from agvdyn.io.columns import label_codes
from agvdyn.simulation import simulate
from agvdyn.trajectories import Trajectory


@pytest.fixture(scope="module")
def result(short_sequence):
    return simulate(Trajectory(short_sequence.segments[:3]), seed=4)


def _columns(n: int = 300, segment: bool = True) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(n)
    t = np.arange(n) * 0.002
    data = {"t": t, "alpha_l": 0.4 * np.sin(t), "alpha_r": np.full(n, -0.3)}
    for w in ("fl", "rl", "fr", "rr"):
        data[f"beta_{w}"] = 2.0 * t + rng.normal(size=n) * 1e-3
        data[f"m_{w}"] = rng.normal(size=n)
    data["alpha_l"][5] = math.pi / 2 + 0.004  # within the stop tolerance: written as it is, not clipped
    if segment:  # runs of known names and rows in no segment ("" and None)
        labels = np.array(["align"] * 50 + [""] * 20 + ["steer_left"] * 100 + [None] * 30 + ["align"] * (n - 200),
                          dtype=object)
        data["segment"] = labels
    return data


def test_simulated_log_is_the_dataframes_file_byte_for_byte(result, tmp_path):
    """result.write (columns, no pandas) against the DataFrame path of before (log_frame), Parquet and CSV."""
    for suffix in (".parquet", ".csv"):
        ours, theirs = tmp_path / f"ours{suffix}", tmp_path / f"theirs{suffix}"
        result.write(ours)
        write_log(theirs, result.log_frame(), result.sidecar())
        assert ours.read_bytes() == theirs.read_bytes(), suffix
        assert (tmp_path / f"ours{suffix}.yaml").read_bytes() == (tmp_path / f"theirs{suffix}.yaml").read_bytes()
    back = read_log(tmp_path / "ours.parquet")
    assert np.array_equal(back.t, result.t) and np.array_equal(back.torque, result.torque_measured)
    assert back.segments.tolist() == result.segment.astype(str).tolist()
    assert pd.read_parquet(tmp_path / "ours.parquet").equals(pd.read_parquet(tmp_path / "theirs.parquet"))


def test_tracking_rows_are_the_tracking_table(result):
    assert result.tracking_rows() == result.tracking().to_dict(orient="records")


@pytest.mark.parametrize("segment", [True, False])
def test_columns_with_missing_labels_or_no_segment_write_the_dataframes_file(tmp_path, segment):
    data = _columns(segment=segment)
    write_log(tmp_path / "ours.parquet", data)
    write_log(tmp_path / "theirs.parquet", pd.DataFrame(data))
    assert (tmp_path / "ours.parquet").read_bytes() == (tmp_path / "theirs.parquet").read_bytes()
    back = read_log(tmp_path / "ours.parquet")
    assert back.clipped["alpha_l"] == 1  # written unclipped, counted when read
    if segment:
        assert back.segments[45:75].tolist() == ["align"] * 5 + [""] * 20 + ["steer_left"] * 5
        assert back.segments[170:200].tolist() == [""] * 30
        assert [run.name for run in back.segment_runs()] == ["align", "steer_left", "align"]


def test_label_codes_are_first_appearance_indices():
    names, codes = label_codes(np.array(["b", "b", "a", "a", "b", "c"]))
    assert names == ["b", "a", "c"] and codes.tolist() == [0, 0, 1, 1, 0, 2]
    assert label_codes(np.array([], dtype=str))[1].size == 0


@pytest.mark.parametrize("change, message", [
    (lambda d: d.pop("m_rr"), r"missing \['m_rr'\]"),
    (lambda d: d.update(extra=d["t"]), r"unexpected \['extra'\]"),
    (lambda d: d.update(m_fl=d["m_fl"] > 0), "column 'm_fl' holds booleans"),
    (lambda d: d.update(m_fl=d["m_fl"].astype(str)), "column 'm_fl' holds <U32 values: expected numbers"),
    (lambda d: d.update(beta_rr=d["beta_rr"][:-1]), r"column 'beta_rr' has shape \(299,\): expected \(300,\)"),
    (lambda d: d.update(segment=d["segment"][:10]), r"column 'segment' has shape \(10,\)"),
    (lambda d: d["segment"].__setitem__(120, "jump"), r"column 'segment', row 120 .*unknown segment name 'jump'"),
    (lambda d: d["t"].__setitem__(7, d["t"][6]), r"column 't', row 7: duplicated time"),
    (lambda d: d["alpha_r"].__setitem__(9, 2.0), r"column 'alpha_r', row 9 .*beyond the mechanical stop"),
    (lambda d: d["beta_fl"].__setitem__(3, np.nan), r"column 'beta_fl', row 3: value nan is not finite"),
])
def test_bad_columns_are_named(tmp_path, change, message):
    data = _columns()
    change(data)
    with pytest.raises(LogError, match=message) as err:
        write_log(tmp_path / "bad.parquet", data)
    assert str(tmp_path / "bad.parquet") in str(err.value)
    assert not (tmp_path / "bad.parquet").exists()


def test_every_column_is_required_in_schema_order(tmp_path):
    data = {c: _columns()[c] for c in reversed(LOG_COLUMNS)}  # any order in: the schema's order out
    write_log(tmp_path / "log.parquet", data)
    assert list(pd.read_parquet(tmp_path / "log.parquet").columns) == list(LOG_COLUMNS)
