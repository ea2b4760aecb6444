"""CSV tables read by pyarrow's parser without pandas (io/table_columns.py, issue 28): the numbers are
Python's correctly rounded ``float`` of each cell, the labels pandas' reading of them, every table
that is not plain goes to pandas (whose messages name the row), and the resulting logs equal the
pandas path's, column for column."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import agvdyn.io.log as log_module
import agvdyn.io.table as table_module
from agvdyn.io.load import load_log
from agvdyn.io.table_columns import csv_columns, parquet_columns
from agvdyn.io.log import LogError, read_log, write_log
from agvdyn.platform import PROTOTYPE
from test_import_cost import _heavy_imports
from test_io_table import DATALOGGER, datalogger_csv


def _write(path: Path, header: list[str], rows: list[list[str]]) -> Path:
    path.write_text("\n".join([",".join(header), *(",".join(r) for r in rows)]) + "\n")
    return path


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
cell = st.one_of(finite.map(repr), finite.map(lambda v: f"{v:.6g}"), finite.map(lambda v: f"{v:.17e}"),
                 st.integers(-2**53, 2**53).map(str))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(cell, cell), min_size=1, max_size=40))
def test_numbers_are_the_correctly_rounded_value_of_each_cell(tmp_path_factory, rows):
    path = _write(tmp_path_factory.mktemp("csv") / "t.csv", ["a", "b"], [list(r) for r in rows])
    cols = csv_columns(path, ["a", "b"])
    assert cols is not None
    for k, name in enumerate(("a", "b")):
        expected = np.array([float(r[k]) for r in rows])
        assert cols[name].dtype == np.float64
        np.testing.assert_array_equal(cols[name], expected)
        # pandas' own parser: the same or one ulp away
        theirs = pd.read_csv(path)[name].to_numpy(dtype=np.float64)
        with np.errstate(over="ignore"):  # the next float after the largest is inf
            one_ulp = (theirs == np.nextafter(expected, np.inf)) | (theirs == np.nextafter(expected, -np.inf))
        assert ((theirs == expected) | one_ulp).all()


@pytest.mark.parametrize("cells, why", [
    (["1.0", "true"], "a boolean"), (["1.0", "x"], "text in a number column"), (["1.0", ""], "an empty field"),
    (["1.0", "NA"], "an NA marker"), (["2024-01-01", "2024-01-02"], "dates"), (["0x10", "2"], "hexadecimal"),
])
def test_a_number_column_that_is_not_plain_goes_to_pandas(tmp_path, cells, why):
    path = _write(tmp_path / "t.csv", ["t", "a"], [["0", cells[0]], ["1", cells[1]]])
    assert csv_columns(path, ["t", "a"]) is None, why
    if why != "hexadecimal":
        assert csv_columns(path, ["t"]) is not None  # only the columns asked for decide


@pytest.mark.parametrize("header", [["t", "t"], ["t", " a"], ["t", ""]])
def test_names_that_pandas_would_change_go_to_pandas(tmp_path, header):
    path = _write(tmp_path / "t.csv", header, [["0", "1"], ["1", "2"]])
    assert csv_columns(path, ["t"]) is None


def test_labels_read_as_pandas_reads_them(tmp_path):
    rows = [["0", "3", " straight ", "x"], ["1", "3", "", "y"], ["2", "4", "NA", "z"], ["3", "4", "rotation", "w"]]
    path = _write(tmp_path / "t.csv", ["t", "phase", "segment", "other"], rows)
    cols = csv_columns(path, ["t"], ["phase", "segment"])
    assert cols["phase"].tolist() == ["3", "3", "4", "4"]
    assert cols["segment"].tolist() == ["straight", None, None, "rotation"]
    many = _write(tmp_path / "many.csv", ["t", "segment"], [[str(k), f"s{k}"] for k in range(300)])
    assert csv_columns(many, ["t"], ["segment"])["segment"].tolist() == [f"s{k}" for k in range(300)]
    gaps = _write(tmp_path / "gaps.csv", ["t", "phase"], [["0", "1"], ["1", ""]])  # pandas: floats, "1.0"
    assert csv_columns(gaps, ["t"], ["phase"]) is None
    assert csv_columns(path, ["t"], ["segment"], exactly=True) is None  # other columns present


def _without_fast_path(monkeypatch):
    monkeypatch.setattr(table_module, "table_columns", lambda *a, **k: None)
    monkeypatch.setattr(log_module, "csv_columns", lambda *a, **k: None)


def _assert_same_log(a, b):
    for col in a.frame.columns:
        if col == "segment":
            assert a.frame[col].astype(object).tolist() == b.frame[col].astype(object).tolist()
        else:
            np.testing.assert_array_equal(a.frame[col].to_numpy(), b.frame[col].to_numpy())
    assert list(a.frame.columns) == list(b.frame.columns)
    assert a.sidecar == b.sidecar and a.clipped == b.clipped


def _our_csv(tmp_path: Path) -> Path:
    """A CSV in our schema with segments: the data logger's table converted and written by write_log."""
    datalogger_csv(tmp_path / "logger.csv", np.arange(0, 6.0, 0.002))
    return write_log(tmp_path / "ours.csv", load_log(tmp_path / "logger.csv", DATALOGGER, PROTOTYPE))


def test_mapped_csv_log_equals_the_pandas_path(tmp_path, monkeypatch):
    path = tmp_path / "logger.csv"
    datalogger_csv(path, np.arange(0, 6.0, 0.002))
    fast = load_log(path, DATALOGGER, PROTOTYPE)
    assert fast.segments is not None
    _without_fast_path(monkeypatch)
    _assert_same_log(fast, load_log(path, DATALOGGER, PROTOTYPE))


def test_our_csv_log_equals_the_pandas_path(tmp_path, monkeypatch):
    path = _our_csv(tmp_path)
    fast = read_log(path)
    assert "segment" in fast.frame.columns
    _without_fast_path(monkeypatch)
    _assert_same_log(fast, read_log(path))


def test_bad_cells_keep_pandas_messages(tmp_path):
    path = _our_csv(tmp_path)
    lines = path.read_text().splitlines()
    cells = lines[5].split(",")
    cells[1] = "oops"
    lines[5] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match=r"column 'alpha_l', row 4 \(line 6 of the file\).*'oops' is not a number"):
        read_log(path)


@pytest.mark.parametrize("phase", ["int", "category", "text"])
def test_mapped_parquet_log_equals_the_pandas_path(tmp_path, monkeypatch, phase):
    datalogger_csv(tmp_path / "logger.csv", np.arange(0, 6.0, 0.002))
    frame = pd.read_csv(tmp_path / "logger.csv")
    frame["cur_FL"] = frame["cur_FL"].astype(np.float32)  # narrower floats are widened alike
    if phase != "int":
        frame["phase"] = frame["phase"].astype(str).astype("category" if phase == "category" else object)
    path = tmp_path / "logger.parquet"
    frame.to_parquet(path)
    cols = parquet_columns(path, ["time_ms", "cur_FL"], ["phase"])
    assert cols["cur_FL"].dtype == np.float64 and cols["phase"][0] in {"0", "1", "4"}
    fast = load_log(path, DATALOGGER, PROTOTYPE)
    _without_fast_path(monkeypatch)
    _assert_same_log(fast, load_log(path, DATALOGGER, PROTOTYPE))


@pytest.mark.parametrize("column, why", [
    (pd.array([0.5, None, 1.0], dtype="Float64"), "a null"), (np.array([True, False, True]), "booleans"),
    (pd.to_datetime(["2024-01-01", "2024-01-02", "2024-01-03"]), "times"),
])
def test_a_parquet_number_column_that_is_not_plain_goes_to_pandas(tmp_path, column, why):
    path = tmp_path / "t.parquet"
    pd.DataFrame({"t": [0.0, 1.0, 2.0], "a": column}).to_parquet(path)
    assert parquet_columns(path, ["t", "a"]) is None, why
    assert parquet_columns(path, ["t"])["t"].tolist() == [0.0, 1.0, 2.0]
    floats = tmp_path / "floats.parquet"
    pd.DataFrame({"t": [0.0, 1.0, 2.0], "phase": [0.0, 1.0, 1.0]}).to_parquet(floats)  # pandas: "0.0"
    assert parquet_columns(floats, ["t"], ["phase"]) is None


def test_inspect_on_a_mapped_csv_imports_no_pandas(tmp_path):
    datalogger_csv(tmp_path / "logger.csv", np.arange(0, 6.0, 0.002))
    mapping = tmp_path / "logger.yaml"
    mapping.write_text(DATALOGGER.read_text() + f"\ni_G: {PROTOTYPE.i_G!r}\n")
    found = _heavy_imports(["inspect", "logger.csv", "--mapping", str(mapping)], tmp_path)
    assert "pandas" not in found, f"inspect on a mapped CSV imported {found}"
