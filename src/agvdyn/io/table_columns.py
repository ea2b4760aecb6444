"""CSV and Parquet tables read straight to numpy columns by pyarrow, without pandas (issue 28:
importing pandas was ~0.12 s of a fresh command on a data-logger CSV).

Only plain tables take this path: unique column names without surrounding blanks, the number
columns all numbers (integers or floats, no empty field, no NA marker), the label columns integers
or text. Anything else (booleans, a text cell in a number column, a missing value, dates, hexadecimal
integers that pyarrow would read but pandas not) returns
None and the caller reads the file with pandas, whose reading gives the messages that name the
first offending row. Numbers are parsed correctly rounded (pyarrow's parser; pandas' own parser may
differ from it in the last bit of a long decimal: tests/test_io_csv_columns.py).
"""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from typing import Any

import numpy as np

from agvdyn.io.columns import label_codes
from agvdyn.io.parquet import _NUMPY_TYPES, _numbers, _parquet_file, _valid

__all__ = ["csv_columns", "parquet_columns", "table_columns", "NA_MARKERS"]

#: Cells that pandas' ``read_csv`` reads as missing by default; here too, so a label column of
#: ``NA`` means "no segment" either way and a number column holding one goes to pandas.
NA_MARKERS = ("", "#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "-nan", "1.#IND", "1.#QNAN",
              "<NA>", "N/A", "NA", "NULL", "NaN", "None", "n/a", "nan", "null")


def csv_columns(path: Path, numbers: Iterable[str], labels: Iterable[str] = (), *, exactly: bool = False
                ) -> dict[str, np.ndarray] | None:
    """The named columns of a CSV file as numpy arrays: ``numbers`` float64, ``labels`` object
    arrays of stripped text (integers written as text; None where empty or NA). Columns the file
    lacks are left out (the caller names them). None when the table is not plain (module docstring)
    or, with ``exactly``, has other columns.
    Arrow buffers are read directly: pyarrow's to_numpy and compute functions import pandas."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    data = Path(path).read_bytes()
    if b"0x" in data or b"0X" in data:  # pyarrow reads hexadecimal integers, pandas text: its messages
        return None
    try:
        table = pcsv.read_csv(
            pa.BufferReader(data),
            read_options=pcsv.ReadOptions(use_threads=False),
            convert_options=pcsv.ConvertOptions(null_values=list(NA_MARKERS), strings_can_be_null=True,
                                                quoted_strings_can_be_null=False, timestamp_parsers=[],
                                                auto_dict_encode=True),
        )
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, UnicodeDecodeError):
        return None
    names = table.column_names
    numbers, labels = list(dict.fromkeys(numbers)), list(dict.fromkeys(labels))
    if len(set(names)) != len(names) or any(n != n.strip() or not n for n in names):
        return None
    if exactly and set(names) - set(numbers) - set(labels):
        return None
    return _columns(table, numbers, labels)


def parquet_columns(path: Path, numbers: Iterable[str], labels: Iterable[str] = ()) -> dict[str, np.ndarray] | None:
    """:func:`csv_columns` for a Parquet file: number columns of integers or floats without nulls,
    label columns of integers without nulls or text (plain or dictionary-encoded)."""
    import pyarrow.parquet as pq

    numbers, labels = list(dict.fromkeys(numbers)), list(dict.fromkeys(labels))
    try:
        names = _parquet_file(path).schema_arrow.names
        text = [c for c in labels if c in names and c not in numbers]  # read as dictionaries: no per-row strings
        file = pq.ParquetFile(path, read_dictionary=text or None)
        wanted = [c for c in dict.fromkeys(numbers + labels) if c in names]
        table = file.read(columns=wanted, use_pandas_metadata=False, use_threads=False)
    except Exception:  # noqa: BLE001 - pandas reads it and says what is wrong
        return None
    if len(set(names)) != len(names):
        return None
    return _columns(table, numbers, labels)


def table_columns(path: Path, numbers: Iterable[str], labels: Iterable[str] = ()) -> dict[str, np.ndarray] | None:
    """:func:`csv_columns` or :func:`parquet_columns` by the file's suffix."""
    read = csv_columns if Path(path).suffix.lower() == ".csv" else parquet_columns
    return read(path, numbers, labels)


def _columns(table: Any, numbers: list[str], labels: list[str]) -> dict[str, np.ndarray] | None:
    """The numbers and labels of an Arrow table that has them (absent ones left out), None if not plain."""
    names = table.column_names
    out: dict[str, np.ndarray] = {}
    for name in numbers:
        if name in names:
            col = table.column(name)
            kind = _NUMPY_TYPES.get(str(col.type))
            if kind is None or col.null_count:
                return None
            out[name] = _numbers(col.chunks, kind).astype(np.float64)
    for name in labels:
        if name in names and name not in out:
            text = _label_text(table.column(name))
            if text is None:
                return None
            out[name] = text
    return out


def _label_text(col: Any) -> np.ndarray | None:
    """A label column's rows as stripped text (None where empty), or None for a column pandas would
    read otherwise (floats; integers with gaps, which pandas reads as floats)."""
    import pyarrow as pa

    if pa.types.is_integer(col.type) and not col.null_count:
        distinct, codes = label_codes(_numbers(col.chunks, _NUMPY_TYPES[str(col.type)]))
        names: list[Any] = [str(v) for v in distinct]
    elif pa.types.is_dictionary(col.type) and _is_text(col.type.value_type) and pa.types.is_integer(col.type.index_type):
        col = col.unify_dictionaries().combine_chunks() if col.num_chunks != 1 else col.chunk(0)
        codes = _numbers([col.indices], _NUMPY_TYPES[str(col.type.index_type)]).astype(np.int64)
        if col.indices.null_count:
            codes[~_valid(col.indices)] = -1
        names = col.dictionary.to_pylist()
    elif _is_text(col.type) or pa.types.is_null(col.type):  # more labels than auto_dict_encode takes
        distinct, codes = label_codes(np.array(col.to_pylist(), dtype=object))
        names = list(distinct)
    else:
        return None
    clean = [None if v is None or not v.strip() else v.strip() for v in names]
    return np.array(clean + [None], dtype=object)[codes]


def _is_text(kind: Any) -> bool:
    import pyarrow as pa

    return pa.types.is_string(kind) or pa.types.is_large_string(kind)
