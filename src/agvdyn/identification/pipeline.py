"""Entry point :func:`identify`: loaded logs (:func:`agvdyn.io.load_logs`, or :func:`agvdyn.io.open_logs`
whose files are read when used, a long one in pieces) -> the row pass of each log once
(:func:`.rows.log_rows`, or the passes the caller already made) -> its rows reduced to normal
equations (:mod:`.normal`) -> the regression steps (:mod:`.fit`). A refusal is diagnosed by
streaming the logs again with sign hypotheses (:mod:`.plausibility`), one log at a time.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import os
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, Union

import numpy as np

from agvdyn.identification._threads import default_workers, ordered_map
from agvdyn.identification.account import LogRows, RowAccount
from agvdyn.identification.change import parameter_change_in_store
from agvdyn.identification.fit import check_fixed, columns, fit_blocks, fit_regression
from agvdyn.identification.model_rows import resolved_model
from agvdyn.identification.normal import LogReduction, RowStatistics, RowStore, merge_reduction, reduce_blocks, regression_data
from agvdyn.identification.plausibility import (
    ImplausibleError,
    diagnose_signs,
    encoder_sign_candidates,
    flipped,
    pick_sign_candidate,
)
from agvdyn.identification.regression import Estimator, UnidentifiableError
from agvdyn.identification.result import Identification
from agvdyn.identification.row_check import with_row_check
from agvdyn.identification.rows import log_rows
from agvdyn.identification.settings import CHASSIS_COORDINATES, DEFAULT_FIXED, OFFSET_NAMES, IdentificationSettings
from agvdyn.identification.stretches import log_source
from agvdyn.identification.workspace import Workspace, keep_freed_memory
from agvdyn.io import Log, LogFile, load_logs, sidecar_platform
from agvdyn.model_spec import PAPER_MODEL, ModelSpec
from agvdyn.platform import PROTOTYPE, Geometry, read_platform

__all__ = ["identify", "fit_blocks", "load_logs", "platform_for", "row_passes", "row_checked"]

#: What :func:`identify` takes: logs in memory, or files read when used.
LoadedLog = Union[Log, LogFile]


def platform_for(logs: Sequence[LoadedLog], platform: Geometry | str | None = None) -> Geometry:
    """The geometry to use: the one given (a Geometry or a platform file), else the ``platform`` of
    the first log's sidecar that has one, else PROTOTYPE."""
    if isinstance(platform, Geometry):
        return platform
    if platform is not None:
        return read_platform(platform)
    for log in logs:
        found = sidecar_platform(log.first() if isinstance(log, LogFile) else log)
        if found is not None:
            return found
    return PROTOTYPE


def row_passes(logs: Sequence[Log], geometry: Geometry, settings: IdentificationSettings = IdentificationSettings(),
               *, model: ModelSpec = PAPER_MODEL) -> list[LogRows]:
    """The row pass of each log in memory (:func:`.rows.log_rows`), blocks kept: what
    :func:`identify`, :func:`agvdyn.preflight.preflight` and the report share (``rows=``; made with the
    same resolved ``model`` as the identification)."""
    return [log_rows(log, geometry, settings, model=model) for log in logs]


def identify(logs: LoadedLog | Sequence[LoadedLog], platform: Geometry | None = None, *,
             fixed: Mapping[str, float] = DEFAULT_FIXED,
             settings: IdentificationSettings = IdentificationSettings(),
             estimator: Estimator | None = None, experiment: str = "auto", keep_blocks: bool = True,
             workers: int | None = None, rows: Sequence[LogRows] | None = None,
             model: ModelSpec = PAPER_MODEL, check_rows: bool = False) -> Identification:
    """Identify the dynamic parameters p (eq. 18) from one or more logs, eq. (22)-(25).

    Logs are reduced one at a time (their kept rows to normal equations, see
    :mod:`agvdyn.identification.normal`): with ``keep_blocks=False`` memory does not grow with the
    number of logs, nor, for files opened with :func:`agvdyn.io.open_logs`, with their length.
    Lifted-wheel logs are identified by :func:`agvdyn.identification.lifted.identify_lifted`.

    Parameters
    ----------
    logs : a :class:`agvdyn.io.Log` or :class:`agvdyn.io.LogFile`, or a sequence of them
        (:func:`agvdyn.io.load_logs`, :func:`agvdyn.io.open_logs`).
    platform : the Geometry; default the sidecar's platform, else the prototype.
    fixed : parameters taken as known (eq. 24), default ``{"B_w": 0.121}``.
    settings : :class:`IdentificationSettings`.
    estimator : an :class:`Estimator`, default the one ``settings.fit.estimator`` names.
    experiment : ``"auto"`` (lifted-wheel logs, by their labels, are refused: identify_lifted) or
        ``"vehicle"`` (the labels are not looked at).
    keep_blocks : keep the equation blocks in the result (Fig. 5/6, residual plots, validation).
    workers : threads that read and reduce logs at once (default :func:`default_workers`: the cores, at most 2); the
        result does not depend on it (logs are merged in their order).
    rows : the row passes of ``logs`` already made (:func:`row_passes`, logs in memory): they are
        used instead of passing the logs again.
    model : a resolved :class:`agvdyn.model_spec.ModelSpec` (default the paper's); a delay ``'auto'`` or
        unknown Stribeck velocities are a ValueError (searched, not fitted by one regression).
    check_rows : also fit the steering parameters on the stick-slip rows and warn where they move beyond
        their stds (:func:`.row_check.steering_row_check`: breakaway friction biases the default rows;
        one more fit, what the ``identify`` command and the report do).

    The first call asks glibc to keep freed memory for reuse (:func:`.workspace.keep_freed_memory`).

    Raises
    ------
    UnidentifiableError
        When the data do not excite some free parameter (message names it and the experiment
        that would excite it).
    ImplausibleError
        A mass, inertia or friction came out negative; the message names the likely sign mistake.
    SignConventionError
        The encoders contradict the rolling constraints unless a sign is changed (named).
    """
    items = _checked_arguments(_items(logs), platform, workers, rows)
    model = resolved_model(model)
    keep_freed_memory()
    geometry = platform if platform is not None else platform_for(items)
    checked = _vehicle_logs(items, experiment)
    jobs = _jobs(items, check_lifted=checked, rows=rows)
    workers = default_workers() if workers is None else int(workers)
    try:
        ident = _fit_stream(jobs, geometry, fixed, settings, estimator, keep_blocks, workers, model)[0]
    except (UnidentifiableError, ImplausibleError) as exc:
        raise _diagnosis(exc, items, geometry, fixed, settings, estimator, model) from None
    return row_checked(ident, items, geometry, fixed, estimator, experiment, workers, model) if check_rows else ident


def row_checked(ident: Identification, items: Sequence[LoadedLog], geometry: Geometry, fixed: Mapping[str, float],
                estimator: Estimator | None, experiment: str, workers: int | None, model: ModelSpec) -> Identification:
    """``ident`` (a fit of ``items`` with ``model``, resolved) with the row check's warnings
    (:func:`.row_check.with_row_check`): the same logs refitted on the stick-slip rows."""
    def refit(other: IdentificationSettings) -> Identification:
        return identify(items, geometry, fixed=fixed, settings=other, estimator=estimator, experiment=experiment,
                        keep_blocks=False, workers=workers, model=model)

    return with_row_check(ident, refit)


def _checked_arguments(items: list[LoadedLog], platform: Any, workers: Any, rows: Any) -> list[LoadedLog]:
    """``items``, after checking :func:`identify`'s other arguments (ValueError naming the bad one)."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers={workers!r}: expected an integer >= 1 (threads reading and reducing logs)")
    if platform is not None and not isinstance(platform, Geometry):
        raise ValueError(f"platform={platform!r}: expected a Geometry (read a platform file with read_platform)")
    if rows is not None and (len(rows) != len(items) or any(isinstance(x, LogFile) for x in items)):
        raise ValueError(f"rows: expected the row passes of the {len(items)} logs in memory, got {len(rows)}")
    return items


def _items(logs: Any) -> list[LoadedLog]:
    if isinstance(logs, (str, os.PathLike)):
        raise ValueError(f"{str(logs)!r}: a path; identify takes loaded logs (agvdyn.io.load_logs, open_logs)")
    items = [logs] if isinstance(logs, (Log, LogFile)) else list(logs)
    if not items:
        raise ValueError("no logs given: expected at least one log")
    for x in items:
        if not isinstance(x, (Log, LogFile)):
            raise ValueError(f"{x!r}: expected a Log or LogFile (load paths with agvdyn.io.load_logs or open_logs)")
    return items


def _source(item: LoadedLog) -> str:
    return str(item.path) if isinstance(item, LogFile) else log_source(item)


def _head(item: LoadedLog) -> Log:
    """The log, or the first piece (or whole log) of a file, not kept."""
    return item.head() if isinstance(item, LogFile) else item


def _vehicle_logs(items: Sequence[LoadedLog], experiment: str) -> bool:
    """Whether the later logs are checked for lifted-wheel labels while they are read (``experiment="auto"``);
    lifted-wheel logs given here are an error (mixed with vehicle logs: naming both)."""
    from agvdyn.identification.lifted import is_lifted, lifted_experiment

    key = str(experiment).strip().lower().replace("_", "-")
    if key not in ("auto", "vehicle"):
        lifted_experiment([], experiment)  # raises for an unknown name
        raise ValueError(f"experiment {experiment!r}: lifted-wheel logs are identified by identify_lifted")
    if key == "vehicle":
        return False
    first = items[0].first() if isinstance(items[0], LogFile) else items[0]
    if is_lifted(first):
        if len(items) > 1:
            lifted_experiment([first] + [_head(x) for x in items[1:]], None)  # raises when mixed
        raise ValueError(f"{getattr(first, 'path', None) or '<log>'} is a lifted-wheel log: identify it with "
                         "agvdyn.identification.identify_lifted (agvdyn identify does so by itself)")
    return True


_Job = Callable[[], tuple[Log, Union[slice, None], Union[LogRows, None]]]


def _jobs(items: Sequence[LoadedLog], *, check_lifted: bool = False, rows: Sequence[LogRows] | None = None,
          flip: tuple[str, ...] = ()) -> Iterator[_Job]:
    """One callable per log (or piece of a long file) that reads it and returns ``(log, core, rows)``
    (``rows`` the pass already made, or None); pieces are read here, in order (each needs its
    neighbour's rows), whole files by the callable. ``flip``: columns negated (sign hypotheses)."""
    for k, item in enumerate(items):
        if isinstance(item, LogFile) and item.long:
            for log, core in item.pieces():
                yield functools.partial(_piece, log, core, flip)
            continue
        first = _source(items[0]) if k > 0 and check_lifted else None
        yield functools.partial(_whole, item, first, None if rows is None else rows[k], flip)


def _piece(log: Log, core: slice, flip: tuple[str, ...]) -> tuple[Log, slice, None]:
    return (flipped(log, flip) if flip else log), core, None


def _whole(item: LoadedLog, first: str | None, rows: LogRows | None, flip: tuple[str, ...]
           ) -> tuple[Log, None, LogRows | None]:
    log = item.load() if isinstance(item, LogFile) else item
    if first is not None:  # vehicle logs: a lifted-wheel one among them is an error
        from agvdyn.identification.lifted import is_lifted, mixed_experiments

        if is_lifted(log):
            raise mixed_experiments([log_source(log)], [first])
    return (flipped(log, flip) if flip else log), None, rows


def _reduced_logs(jobs: Iterator[_Job], geometry: Geometry, settings: IdentificationSettings, width: int,
                  order: np.ndarray, workers: int, reuse: bool, model: ModelSpec = PAPER_MODEL
                  ) -> Iterator[tuple[Log, Any, LogRows, LogReduction]]:
    """``(log, core, rows, reduction)`` of every log, in order: read, its row pass made (unless
    given) and its rows reduced (:func:`.normal.reduce_blocks`) in up to ``workers`` threads at a
    time (the compiled kernels, pyarrow and LAPACK release the GIL), at most ``workers + 1`` logs
    ahead. ``reuse``: the blocks are not wanted (``rows.blocks`` empty), each thread reuses its buffers."""

    local = threading.local()

    def work(job: _Job):
        log, core, rows = job()
        space = None
        if reuse and rows is None:  # the blocks are dropped once reduced: the next log of this thread reuses the buffers
            space = local.__dict__.setdefault("workspace", Workspace())
        if rows is None:
            rows = log_rows(log, geometry, settings, core, space, model)
        reduction = reduce_blocks(rows.blocks, width, offsets=settings.fit.torque_offsets, columns=order,
                                  workspace=space)
        if reuse:
            rows = dataclasses.replace(rows, blocks=())
        return log, core, rows, reduction

    yield from ordered_map(work, jobs, workers, "agvdyn-identify")


def _fit_stream(jobs: Iterator[_Job], geometry: Geometry, fixed: Mapping[str, float],
                settings: IdentificationSettings, estimator: Estimator | None, keep_blocks: bool,
                workers: int = 1, model: ModelSpec = PAPER_MODEL) -> tuple[Identification, float]:
    """Rows of each log reduced to normal equations as it is read (:mod:`.normal`), then one
    regression (:func:`.fit.fit_regression`); the identification and its residual RMS over all rows."""
    fixed = check_fixed(fixed)
    _, _, idx_free, p_fixed = columns(fixed, settings.fit.torque_offsets, model)
    order = np.array(list(idx_free) + [i for i in range(len(p_fixed)) if i not in idx_free])  # free columns first
    stats, store, names = RowStatistics(len(p_fixed), columns=order), RowStore(columns=order), {}
    account = RowAccount()
    consumed = 0  # own rows of the earlier pieces of a long log: the sample index of this piece's first own row
    timing: list[tuple[str, float, float]] = []  # per stored recording: log, first time, sample time
    try:
        for log, core, rows, reduction in _reduced_logs(jobs, geometry, settings, len(p_fixed), order, workers,
                                                        reuse=not keep_blocks, model=model):
            source = str(getattr(log, "path", None) or "<log>")
            if core is None or not account.sources or account.sources[-1] != source:
                consumed, t0 = 0, float(log.t[0])
            stored = len(store)
            merge_reduction(reduction, stats, store, names, step_offset=0 if core is None else consumed - core.start)
            timing += [(source, t0, log.sample_time)] * (len(store) - stored)
            if core is not None:
                consumed += core.stop - core.start
            account.add(rows, source, piece=core is not None, keep_blocks=keep_blocks)
        _check_segments_present(account.labels, settings)
        if not stats.n_rows:
            raise ValueError(
                "no usable rows: the logs contain no samples in a motion mode of the model "
                f"(segments used: {', '.join(settings.rows.segments) if settings.rows.segments else 'all'}; "
                f"rows: {account.counts.to_dict()})")
        data = regression_data(stats, names, idx_free, p_fixed, store)
        ident = fit_regression(data, geometry, fixed=fixed, settings=settings, estimator=estimator, account=account,
                               workers=workers, model=model)
        chassis = [code for code, name in enumerate(data.group_names) if name in CHASSIS_COORDINATES]
        ident = _with_parameter_change(ident, store, timing, chassis, workers)
        total = sum(ident.residual_rms.get(f"{s}:{c}", 0.0) ** 2 * n for (s, c), n in zip(data.keys, data.key_rows))
        return ident, math.sqrt(total / data.n_rows)
    finally:
        store.close()


def _with_parameter_change(ident: Identification, store: RowStore, timing: list[tuple[str, float, float]],
                           chassis: list[int], workers: int = 1) -> Identification:
    """The identification with the m_ch / C_ch change found within a recording, if any
    (:func:`.change.parameter_change_in_store`): a warning naming the time, and ``parameter_change``."""
    theta = ident.parameters.to_vector()
    if ident.offsets:
        theta = np.concatenate([theta, [ident.offsets[n] for n in OFFSET_NAMES]])
    if ident.extra_vector is not None:  # the model's columns follow the offsets in the store
        theta = np.concatenate([theta, ident.extra_vector])
    changes = parameter_change_in_store(store, theta, timing, rows=chassis, workers=workers)
    if not changes:
        return ident
    first = changes[0]
    size = ", ".join(f"{n} {v:+.4g} +- {first.std[n]:.2g}" for n, v in first.size.items() if v is not None)
    warning = (f"parameter change within {first.recording} at t = {first.t:.1f} s: the chassis equations change "
               f"as if {size}; a load picked up or dropped, or another effect the model lacks (wheel slip, a drive "
               "fault); the parameters average both parts. If the load changed, identify each part alone or follow "
               "it with agvdyn track (docs/online.md)")
    return dataclasses.replace(ident, parameter_change=first.to_dict(), warnings=ident.warnings + (warning,))


def _diagnosis(exc: Exception, items: Sequence[LoadedLog], geometry: Geometry, fixed: Mapping[str, float],
               settings: IdentificationSettings, estimator: Estimator | None,
               model: ModelSpec = PAPER_MODEL) -> Exception:
    """The error to raise for a refusal: a sign mistake the encoders or the torques reveal, or
    ``exc`` (with the likely cause, for an implausible estimate). Each hypothesis streams the logs
    again, one at a time (the first piece of a long file for the encoders)."""
    lenient = settings.replace(plausibility=False, uncertainty="classic")  # values and residuals only

    def refit(flip: tuple[str, ...], checked: IdentificationSettings = lenient) -> tuple[Identification, float]:
        return _fit_stream(_jobs(items, flip=flip), geometry, fixed, checked, estimator, False, model=model)

    candidates = encoder_sign_candidates((_head(x) for x in items), geometry, settings)  # the rolling constraints first
    if candidates:
        return pick_sign_candidate(candidates, lambda flip: refit(flip)[0])
    if isinstance(exc, UnidentifiableError):
        return exc
    unchecked = refit((), lenient.replace(max_relative_std=math.inf))
    cause, detail = diagnose_signs(refit, unchecked[1])
    return ImplausibleError(exc.implausible, cause, detail)


def _check_segments_present(present: set[str], settings: IdentificationSettings) -> None:
    """``settings.rows.segments`` must name labels some log carries; else an error listing the ones present."""
    if settings.rows.segments is None:
        return
    missing = [s for s in settings.rows.segments if s not in present]
    if missing:
        raise ValueError(f"segments {missing} are not in the logs: the logs carry the labels "
                         f"{sorted(present) or 'none (no segment column)'}")
