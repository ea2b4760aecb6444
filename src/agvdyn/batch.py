"""Batch identification of a fleet (``agvdyn batch``): one job per vehicle, run on Dask.

A YAML manifest lists the jobs::

    defaults:                   # optional: keys every job takes unless it sets them itself
      estimator: wls
    jobs:
      - name: agv-07
        logs: [agv07/ident1.parquet, agv07/ident2.parquet]
        platform: platforms/agv07.yaml
        fix: {B_w: 0.121}         # 'none' (or {}) estimates all eleven; without it: the default B_w=0.121
        mapping: mappings/bag.yaml
        estimator: robust
        uncertainty: hac
        settings: {stiction_threshold: 0.05}   # further IdentificationSettings keywords (flat names, from_flat)
        tags: {fleet: north, tyres: new}

Relative paths are taken from the manifest's folder. Each job is a pure function of its inputs
(:func:`run_job`, a :class:`BatchJob` in, rows out), identified with
:func:`agvdyn.identification.identify`; a job that fails (missing file, unexcited data, ...) is one
row carrying its error, never an exception of the batch. :func:`run_batch` runs the jobs on a
``dask.distributed`` cluster (a LocalCluster of processes, one thread each, or an existing
scheduler) and returns the table: one row per job and parameter, columns :data:`TABLE_COLUMNS`.
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["BatchJob", "ManifestError", "read_manifest", "jobs_from_dict", "run_job", "run_batch", "map_on_dask",
           "TABLE_COLUMNS"]

#: Columns of the batch table (a contract: add, don't rename).
TABLE_COLUMNS = ("job", "parameter", "value", "std", "ci_low", "ci_high", "fixed", "cond", "rows", "seconds",
                 "estimator", "uncertainty", "tags", "logs", "error")

#: Keys of a job in the manifest.
JOB_KEYS = ("name", "logs", "platform", "mapping", "fix", "estimator", "uncertainty", "settings", "tags")

_Z95 = 1.959963984540054  # two-sided 95 % quantile of the normal distribution


class ManifestError(ValueError):
    """A manifest that cannot be used; the message names the file, the job and the key."""


@dataclass(frozen=True)
class BatchJob:
    """One identification: logs (absolute paths), platform and mapping files (or None), parameters taken
    as known (None: the identification default), estimator and uncertainty names (None: default), further
    IdentificationSettings keywords, and tags copied into the table."""

    name: str
    logs: tuple[str, ...]
    platform: str | None = None
    mapping: str | None = None
    fix: dict[str, float] | None = None
    estimator: str | None = None
    uncertainty: str | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    tags: str = ""

    def identification_settings(self) -> Any:
        from agvdyn.identification import IdentificationSettings

        keywords = dict(self.settings)
        if self.estimator is not None:
            keywords["estimator"] = self.estimator
        if self.uncertainty is not None:
            keywords["uncertainty"] = self.uncertainty
        return IdentificationSettings.from_flat(**keywords)

    def fixed(self) -> dict[str, float]:
        from agvdyn.identification import DEFAULT_FIXED

        return dict(DEFAULT_FIXED) if self.fix is None else dict(self.fix)


def _tags(value: Any, where: str) -> str:
    if value is None:
        return ""
    if isinstance(value, Mapping):
        return ",".join(f"{k}={v}" for k, v in value.items())
    if isinstance(value, str):
        return value
    if isinstance(value, Sequence):
        return ",".join(str(v) for v in value)
    raise ManifestError(f"{where}: tags: expected a mapping or a list, got {type(value).__name__}")


def _path(value: Any, base: Path, where: str) -> str:
    if not isinstance(value, (str, os.PathLike)) or not str(value):
        raise ManifestError(f"{where}: expected a file path, got {value!r}")
    p = Path(os.path.expanduser(str(value)))
    return str(p if p.is_absolute() else base / p)


def _fix(value: Any, where: str) -> dict[str, float] | None:
    if value is None:
        return None
    if isinstance(value, str) and value.strip().lower() == "none":
        return {}
    if not isinstance(value, Mapping):
        raise ManifestError(f"{where}: fix: expected a mapping NAME: VALUE or 'none', got {value!r}")
    out = {}
    for name, v in value.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ManifestError(f"{where}: fix: {name}: expected a finite number, got {v!r}")
        out[str(name)] = float(v)
    return out


def jobs_from_dict(data: Any, base: str | os.PathLike = ".", source: str = "manifest") -> list[BatchJob]:
    """The jobs of a manifest's contents (``{'jobs': [...], 'defaults': {...}}``), paths relative to ``base``."""
    base = Path(base)
    if not isinstance(data, Mapping) or "jobs" not in data:
        raise ManifestError(f"{source}: expected a mapping with a 'jobs' list")
    unknown = sorted(set(data) - {"jobs", "defaults"})
    if unknown:
        raise ManifestError(f"{source}: unknown top-level key(s) {unknown}: expected jobs, defaults")
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, Mapping):
        raise ManifestError(f"{source}: defaults: expected a mapping")
    bad = sorted(set(defaults) - set(JOB_KEYS[1:]))
    if bad:
        raise ManifestError(f"{source}: defaults: unknown key(s) {bad}: expected {list(JOB_KEYS[1:])}")
    entries = data["jobs"]
    if not isinstance(entries, list) or not entries:
        raise ManifestError(f"{source}: jobs: expected a non-empty list")
    jobs, names = [], set()
    for i, entry in enumerate(entries):
        where = f"{source}: jobs[{i}]"
        if not isinstance(entry, Mapping):
            raise ManifestError(f"{where}: expected a mapping")
        entry = {**defaults, **entry}
        unknown = sorted(set(entry) - set(JOB_KEYS))
        if unknown:
            raise ManifestError(f"{where}: unknown key(s) {unknown}: expected {list(JOB_KEYS)}")
        name = str(entry.get("name") or f"job{i}")
        where = f"{source}: job {name!r}"
        if name in names:
            raise ManifestError(f"{where}: the name is used twice")
        names.add(name)
        logs = entry.get("logs")
        if isinstance(logs, (str, os.PathLike)):
            logs = [logs]
        if not isinstance(logs, list) or not logs:
            raise ManifestError(f"{where}: logs: expected a non-empty list of files")
        settings = entry.get("settings") or {}
        if not isinstance(settings, Mapping):
            raise ManifestError(f"{where}: settings: expected a mapping of IdentificationSettings keywords")
        for key in ("estimator", "uncertainty"):
            if entry.get(key) is not None and not isinstance(entry[key], str):
                raise ManifestError(f"{where}: {key}: expected a name, got {entry[key]!r}")
        jobs.append(BatchJob(
            name=name, logs=tuple(_path(p, base, f"{where}: logs") for p in logs),
            platform=None if entry.get("platform") is None else _path(entry["platform"], base, f"{where}: platform"),
            mapping=None if entry.get("mapping") is None else _path(entry["mapping"], base, f"{where}: mapping"),
            fix=_fix(entry.get("fix"), where), estimator=entry.get("estimator"),
            uncertainty=entry.get("uncertainty"), settings=dict(settings), tags=_tags(entry.get("tags"), where)))
    return jobs


def read_manifest(path: str | os.PathLike) -> list[BatchJob]:
    """The jobs of a manifest file (YAML); relative paths are taken from the manifest's folder."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ManifestError(f"{path}: cannot be read as YAML: {exc}") from exc
    return jobs_from_dict(data, path.resolve().parent, str(path))


def _error_row(job: BatchJob, error: str, seconds: float = math.nan) -> dict[str, Any]:
    return {"job": job.name, "parameter": "", "value": math.nan, "std": math.nan, "ci_low": math.nan,
            "ci_high": math.nan, "fixed": False, "cond": math.nan, "rows": 0, "seconds": seconds,
            "estimator": job.estimator or "", "uncertainty": job.uncertainty or "", "tags": job.tags,
            "logs": ";".join(job.logs), "error": error}


def _message(exc: BaseException) -> str:
    text = str(exc).strip() or repr(exc)
    return f"{type(exc).__name__}: {text}"


def run_job(job: BatchJob) -> list[dict[str, Any]]:
    """Identify one job; rows of the batch table (one per parameter, or one carrying the error)."""
    t0 = time.perf_counter()
    try:
        from agvdyn.identification import identify, platform_for
        from agvdyn.io import open_logs
        from agvdyn.platform import PARAMETER_NAMES

        settings = job.identification_settings()
        logs = open_logs(list(job.logs), mapping=job.mapping, platform=job.platform)
        ident = identify(logs, platform_for(logs, job.platform), fixed=job.fixed(), settings=settings,
                         keep_blocks=False, workers=1)  # one thread per Dask worker process
    except Exception as exc:  # noqa: BLE001 - a failed job is a row, never a failed batch
        return [_error_row(job, _message(exc), time.perf_counter() - t0)]
    seconds = time.perf_counter() - t0
    rows = []
    for name in PARAMETER_NAMES:
        value = float(getattr(ident.parameters, name))
        fixed = name in ident.fixed
        std = math.nan if fixed else float(ident.std.get(name, math.nan))
        rows.append({"job": job.name, "parameter": name, "value": value, "std": std,
                     "ci_low": value - _Z95 * std, "ci_high": value + _Z95 * std, "fixed": fixed,
                     "cond": float(ident.condition_number), "rows": int(ident.n_rows), "seconds": seconds,
                     "estimator": settings.fit.estimator.value,
                     "uncertainty": settings.uncertainty.method.value if ident.uncertainty is None
                     else str(ident.uncertainty.method),
                     "tags": job.tags, "logs": ";".join(job.logs), "error": ""})
    return rows


def map_on_dask(func: Callable[[Any], Any], items: Sequence[Any], *, scheduler: str | None = None,
                workers: int = 1, progress: Callable[[int, int], None] | None = None
                ) -> Iterator[tuple[int, Any, BaseException | None]]:
    """``func`` over ``items`` on Dask: yields ``(index, result, None)`` or ``(index, None, exception)`` as
    they complete. ``scheduler``: address of a running scheduler (``tcp://host:port``); without it a
    LocalCluster of ``workers`` processes with one thread each, closed at the end."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler, timeout="30s")
    try:
        futures = client.map(func, list(items), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        done = 0
        for future in as_completed(futures):
            i = index[future.key]
            try:
                result, error = future.result(), None
            except Exception as exc:  # noqa: BLE001 - a lost worker or an unpicklable result
                result, error = None, exc
            done += 1
            if progress:
                progress(done, len(futures))
            yield i, result, error
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_batch(jobs: Sequence[BatchJob], *, workers: int = 1, scheduler: str | None = None,
              progress: Callable[[int, int], None] | None = None) -> Any:
    """Run the jobs on Dask (see :func:`map_on_dask`) and return the table (pandas), in the order of the
    jobs, one row per job and parameter (:data:`TABLE_COLUMNS`)."""
    import pandas as pd

    results: list[list[dict[str, Any]]] = [[] for _ in jobs]
    for i, rows, error in map_on_dask(run_job, jobs, scheduler=scheduler, workers=workers, progress=progress):
        results[i] = rows if error is None else [_error_row(jobs[i], _message(error))]
    frame = pd.DataFrame([row for rows in results for row in rows], columns=list(TABLE_COLUMNS))
    return frame.astype({"rows": "int64", "fixed": "bool"})
