"""Reading Parquet logs in our schema with pyarrow, straight into numpy (:func:`agvdyn.io.log.read_log`):
the footer is read once per file version, and the columns come from pyarrow's buffers, so that
reading our logs imports no pandas. Files other tools wrote with our column names take the same
way: float32 or integer columns (widened to float64 exactly as pandas does), and a ``segment``
column stored as plain strings (read as a dictionary: the labels are compared once per distinct
name, not once per row) or as a categorical."""
from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import numpy as np

from agvdyn.io.schema import LOG_COLUMNS, SEGMENT_COLUMN, SEGMENTS, LogError

__all__ = ["parquet_metadata", "our_parquet_columns", "write_our_parquet", "write_parquet_columns"]


def parquet_metadata(path: str | os.PathLike) -> Any:
    """The footer (``pyarrow.parquet.FileMetaData``) of a Parquet file, read once per file version
    (path, size and modification time): the row count asked before a log is read and the read
    itself share it."""
    with _FOOTERS_LOCK:
        footer = _FOOTERS.get(_version(path))
    return footer if footer is not None else _parquet_file(path).metadata


_FOOTERS: dict[tuple[str, int, int], Any] = {}
_FOOTERS_LOCK = threading.Lock()


def _parquet_file(path: str | os.PathLike, read_dictionary: bool = False) -> Any:
    """``pyarrow.parquet.ParquetFile(path)`` with the footer already read for this file version, if any;
    with ``read_dictionary`` a ``segment`` column, if there is one, is read as a dictionary array."""
    import pyarrow.parquet as pq

    key = _version(path)
    with _FOOTERS_LOCK:
        footer = _FOOTERS.get(key)
    if read_dictionary:
        if footer is None:
            footer = _parquet_file(path).metadata
        segment = SEGMENT_COLUMN in footer.schema.names  # a missing column in read_dictionary is an error
        return pq.ParquetFile(path, metadata=footer, read_dictionary=[SEGMENT_COLUMN] if segment else None)
    file = pq.ParquetFile(path, metadata=footer)
    if footer is None:
        with _FOOTERS_LOCK:  # the few most recent files: a log is asked for twice in a row
            _FOOTERS[key] = file.metadata
            while len(_FOOTERS) > 8:
                _FOOTERS.pop(next(iter(_FOOTERS)))
    return file


def _version(path: str | os.PathLike) -> tuple[str, int, int]:
    stat = os.stat(path)
    return str(path), stat.st_size, stat.st_mtime_ns


def write_our_parquet(path: str | os.PathLike, frame: Any) -> None:
    """Write a checked log (a DataFrame of our columns) as Parquet: floats plain and uncompressed
    (noisy samples hardly compress: +15 % size, half the read time) in required (non-nullable)
    columns, which pyarrow reads without definition levels (0.9 against 1.4 ms per 35,500-sample
    log), the segment labels dictionary-encoded. pandas' metadata is kept (``pd.read_parquet``
    gives the same frame back)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(frame, preserve_index=False)
    fields = [f.with_nullable(False) if f.name in LOG_COLUMNS else f for f in table.schema]
    table = table.cast(pa.schema(fields, metadata=table.schema.metadata))
    segment = [SEGMENT_COLUMN] if SEGMENT_COLUMN in table.column_names else False
    pq.write_table(table, path, compression="none", use_dictionary=segment)


def write_parquet_columns(path: str | os.PathLike, lazy: Any) -> None:
    """Write checked columns (a :class:`agvdyn.io.schema.LazyFrame`: the float block and the segment
    codes) as :func:`write_our_parquet` writes their DataFrame, byte for byte (the same Arrow schema,
    pandas' metadata included), without pandas."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from importlib.metadata import version

    pandas_version = version("pandas")
    fields = [pa.field(name, pa.float64(), nullable=False) for name in LOG_COLUMNS]
    arrays = [_arrow_array(pa.float64(), lazy.block[:, k]) for k in range(len(LOG_COLUMNS))]
    if lazy.segment_codes is not None:
        codes = np.asarray(lazy.segment_codes, dtype=np.int8)
        # pandas 3's categories are its "str" dtype: Arrow's large strings (pandas 2: objects, strings)
        large = int(pandas_version.split(".")[0]) >= 3
        text = "".join(SEGMENTS).encode()
        ends = np.cumsum([0] + [len(name.encode()) for name in SEGMENTS])
        labels = pa.Array.from_buffers(pa.large_string() if large else pa.string(), len(SEGMENTS),
                                       [None, pa.py_buffer(ends.astype(np.int64 if large else np.int32)),
                                        pa.py_buffer(text)])
        arrays.append(pa.DictionaryArray.from_arrays(_arrow_array(pa.int8(), codes, valid=codes >= 0), labels))
        fields.append(pa.field(SEGMENT_COLUMN, arrays[-1].type))
    metadata = {b"pandas": _pandas_metadata(lazy.segment_codes is not None, pa.__version__, pandas_version).encode()}
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=metadata))
    segment = [SEGMENT_COLUMN] if lazy.segment_codes is not None else False
    pq.write_table(table, path, compression="none", use_dictionary=segment)


def _arrow_array(kind: Any, values: np.ndarray, valid: np.ndarray | None = None) -> Any:
    """An Arrow array of a numpy column from its buffers (``pa.array`` imports pandas, ~0.15 s),
    missing where ``valid`` is False."""
    import pyarrow as pa

    bitmap = None
    if valid is not None and not valid.all():
        bitmap = pa.py_buffer(np.packbits(valid, bitorder="little"))
    null_count = 0 if bitmap is None else int(valid.size - np.count_nonzero(valid))
    return pa.Array.from_buffers(kind, values.shape[0], [bitmap, pa.py_buffer(np.ascontiguousarray(values))],
                                 null_count=null_count)


def _pandas_metadata(segment: bool, pyarrow_version: str, pandas_version: str) -> str:
    """The ``pandas`` schema metadata ``pa.Table.from_pandas`` writes for a checked log (our float
    columns, the segment a categorical over :data:`SEGMENTS`, no index), so that ``pd.read_parquet``
    gives the same frame back (``pandas_version``: the installed one's, read without importing it)."""
    import json

    columns = [{"name": n, "field_name": n, "pandas_type": "float64", "numpy_type": "float64", "metadata": None}
               for n in LOG_COLUMNS]
    if segment:
        columns.append({"name": SEGMENT_COLUMN, "field_name": SEGMENT_COLUMN, "pandas_type": "categorical",
                        "numpy_type": "int8", "metadata": {"num_categories": len(SEGMENTS), "ordered": False}})
    return json.dumps({"index_columns": [], "column_indexes": [], "columns": columns, "attributes": {},
                       "creator": {"library": "pyarrow", "version": pyarrow_version},
                       "pandas_version": pandas_version})


def our_parquet_columns(path: Path) -> tuple[dict[str, np.ndarray], tuple[list[str | None], np.ndarray] | None] | None:
    """The columns of a Parquet file that holds exactly our columns (floating or integer numbers
    without nulls, an optional ``segment`` column of strings, plain or dictionary-encoded) as numpy
    arrays (float64 or narrower, widened by the caller) and the segment's (names, codes); None for
    any other file (read then through pandas, with its messages: booleans, nulls, extra columns)."""
    import pyarrow as pa

    try:
        # no pyarrow threads: logs are read in the identification's own threads (nested pools oversubscribed the cores)
        table = _parquet_file(path, read_dictionary=True).read(use_pandas_metadata=False, use_threads=False)
    except Exception as exc:  # noqa: BLE001 - any pyarrow failure: the file is not readable Parquet
        raise LogError(f"{path}: cannot be read as parquet: {exc}") from exc
    names = table.column_names
    if len(set(names)) != len(names) or set(names) - {*LOG_COLUMNS, SEGMENT_COLUMN} or set(LOG_COLUMNS) - set(names):
        return None
    columns = {}
    for name in LOG_COLUMNS:
        column = table.column(name)
        kind = _NUMPY_TYPES.get(str(column.type))
        if kind is None or column.null_count:
            return None
        columns[name] = _numbers(column.chunks, kind)
    if SEGMENT_COLUMN not in names:
        return columns, None
    segment = table.column(SEGMENT_COLUMN)
    if not pa.types.is_dictionary(segment.type) or not (
            pa.types.is_string(segment.type.value_type) or pa.types.is_large_string(segment.type.value_type)):
        return None
    if not pa.types.is_integer(segment.type.index_type):
        return None
    segment = segment.unify_dictionaries().combine_chunks() if segment.num_chunks != 1 else segment.chunk(0)
    width = segment.type.index_type.bit_width
    kind = np.dtype(f"{'int' if pa.types.is_signed_integer(segment.type.index_type) else 'uint'}{width}")
    indices = segment.indices
    codes = _numbers([indices], kind).astype(np.int64)
    if indices.null_count:  # missing labels: -1
        codes[~_valid(indices)] = -1
    return columns, (segment.dictionary.to_pylist(), codes)


#: Arrow types of number columns read straight into numpy (as pandas reads them: the same values
#: after widening to float64); any other type (booleans, float16, decimals, times) goes through pandas.
_NUMPY_TYPES = {"double": np.float64, "float": np.float32, **{
    f"{sign}int{bits}": np.dtype(f"{sign}int{bits}") for sign in ("", "u") for bits in (8, 16, 32, 64)}}


def _numbers(chunks: list[Any], dtype: np.dtype) -> np.ndarray:
    """The values of primitive Arrow arrays as one numpy array, read from their data buffers
    (pyarrow's to_numpy and compute functions import pandas: ~0.4 s that reading our logs never needs)."""
    dtype = np.dtype(dtype)
    parts = [np.frombuffer(c.buffers()[1], dtype=dtype, count=len(c), offset=c.offset * dtype.itemsize)
             for c in chunks if len(c)]
    return parts[0] if len(parts) == 1 else np.concatenate(parts) if parts else np.zeros(0, dtype)


def _valid(array: Any) -> np.ndarray:
    """Which entries of an Arrow array are not null, from its validity bitmap (LSB first)."""
    bits = np.unpackbits(np.frombuffer(array.buffers()[0], dtype=np.uint8), bitorder="little")
    return bits[array.offset:array.offset + len(array)].astype(bool)
