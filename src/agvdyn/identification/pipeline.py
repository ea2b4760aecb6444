"""Entry point :func:`identify`: logs read one at a time (long ones in pieces) -> rows (stretches
filtered once, rows classified) -> normal equations -> regression (:mod:`.fit`)."""
from __future__ import annotations

import dataclasses
import functools
import math
import os
import threading
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from agvdyn.identification.fit import check_fixed, columns, fit_blocks, fit_regression
from agvdyn.identification.normal import LogReduction, RowStatistics, RowStore, merge_reduction, reduce_blocks, regression_data
from agvdyn.identification.plausibility import (
    ImplausibleError,
    diagnose_signs,
    encoder_sign_candidates,
    overall_rms,
    pick_sign_candidate,
)
from agvdyn.identification.regression import Estimator, UnidentifiableError
from agvdyn.identification.result import Identification
from agvdyn.identification.rows import RowCounts, labels_present, log_rows
from agvdyn.identification.settings import DEFAULT_FIXED, IdentificationSettings
from agvdyn.identification._threads import default_workers, ordered_map
from agvdyn.identification.workspace import Workspace, keep_freed_memory
from agvdyn.identification.slip import SlipEvent
from agvdyn.identification.equations import EquationBlock
from agvdyn.platform import PROTOTYPE, Geometry, read_platform

__all__ = ["identify", "fit_blocks", "load_logs", "platform_for"]


def load_logs(logs: Any, *, mapping: Any = None, platform: Geometry | str | os.PathLike | None = None,
              stop_tolerance: float | None = None) -> list[Any]:
    """Logs as :class:`agvdyn.io.Log` objects: paths are loaded and checked with
    ``agvdyn.io.load_log(path, mapping, platform)`` (mapping: for tables and bags not in our
    schema), Log objects are passed through."""
    from agvdyn.io import STOP_TOLERANCE, load_log

    if isinstance(logs, (str, os.PathLike)) or hasattr(logs, "alpha"):
        logs = [logs]
    tol = STOP_TOLERANCE if stop_tolerance is None else stop_tolerance
    out = [load_log(x, mapping, platform, stop_tolerance=tol) if isinstance(x, (str, os.PathLike)) else x for x in logs]
    if not out:
        raise ValueError("no logs given: expected at least one log")
    return out


def platform_for(logs: Sequence[Any], platform: Geometry | str | os.PathLike | None) -> Geometry:
    """The geometry to use: the one given, else the ``platform`` of the first log's sidecar, else PROTOTYPE."""
    from agvdyn.io import Log, sidecar_platform

    if isinstance(platform, Geometry):
        return platform
    if platform is not None:
        return read_platform(platform)
    for log in logs:
        if isinstance(log, Log) or getattr(log, "sidecar", None):  # a Log's sidecar is read on demand
            found = sidecar_platform(log)
            if found is not None:
                return found
    return PROTOTYPE


def identify(logs: Any, platform: Geometry | str | os.PathLike | None = None, *,
             fixed: Mapping[str, float] = DEFAULT_FIXED,
             settings: IdentificationSettings = IdentificationSettings(),
             estimator: Estimator | None = None, experiment: str | None = None, mapping: Any = None,
             keep_blocks: bool = True, workers: int | None = None) -> Identification:
    """Identify the dynamic parameters p (eq. 18) from one or more logs, eq. (22)-(25).

    Logs are read and reduced one at a time (their kept rows to normal equations, see
    :mod:`agvdyn.identification.normal`): with ``keep_blocks=False`` memory does not grow with the
    number of logs. Lifted-wheel logs (every labelled row ``lifted_wheel``, or
    ``experiment="lifted-wheel"``) give B_w and the unloaded wheel friction instead: a
    :class:`~agvdyn.identification.lifted.LiftedWheelIdentification`.

    Parameters
    ----------
    logs : path, Log, or a sequence of them (paths are read with :func:`agvdyn.io.load_log`).
    platform : Geometry or platform file; default the sidecar's platform, else the prototype.
    fixed : parameters taken as known (eq. 24), default ``{"B_w": 0.121}``.
    settings : :class:`IdentificationSettings`.
    estimator : an :class:`Estimator`, default the one ``settings.fit.estimator`` names.
    experiment : ``"auto"``/None (from the labels), ``"vehicle"`` or ``"lifted-wheel"``.
    mapping : mapping file or :class:`agvdyn.io.LogMapping` for logs not in our schema.
    keep_blocks : keep the equation blocks in the result (Fig. 5/6, residual plots, validation).
    workers : threads that read and reduce logs at once (default :func:`default_workers`: the cores, at most 2); the
        result does not depend on it (logs are merged in their order).

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
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers={workers!r}: expected an integer >= 1 (threads reading and reducing logs)")
    keep_freed_memory()
    items = [logs] if isinstance(logs, (str, os.PathLike)) or hasattr(logs, "alpha") else list(logs)
    if not items:
        raise ValueError("no logs given: expected at least one log")
    geometry_in = platform if isinstance(platform, Geometry) else None
    load = (lambda x: x if hasattr(x, "alpha") else load_logs([x], mapping=mapping, platform=platform)[0])
    pieces = None if mapping is not None else _pieces_of
    first = next(iter(pieces(items[0]) or [(None, None)]))[0] if pieces else None
    first = first if first is not None else load(items[0])
    geometry = geometry_in if geometry_in is not None else platform_for([first], platform)
    from agvdyn.identification.lifted import identify_lifted, is_lifted, lifted_experiment

    explicit = experiment is not None and str(experiment).strip().lower() != "auto"
    if lifted_experiment([first], experiment) and (explicit or len(items) == 1):
        return identify_lifted([first] + [load(x) for x in items[1:]], geometry, settings=settings,
                               estimator=estimator)
    if not explicit and is_lifted(first):  # more logs: every one must be lifted, else the error of mixing them
        loaded = [first] + [load(x) for x in items[1:]]
        lifted_experiment(loaded, experiment)
        return identify_lifted(loaded, geometry, settings=settings, estimator=estimator)
    stream = _LogStream(items, load, first, lifted=None if explicit else is_lifted, pieces=pieces)
    try:
        return _identify_stream(stream, geometry, fixed, settings, estimator, keep_blocks,
                                default_workers() if workers is None else int(workers))
    except (UnidentifiableError, ImplausibleError) as exc:
        loaded = [load(x) for x in items]
        # the diagnosis compares values and residuals only: the classic covariance is enough
        lenient = settings.replace(plausibility=False, uncertainty="classic")

        def refit(flipped: Sequence[Any], checked: IdentificationSettings = lenient) -> Identification:
            return _identify_stream(_LogStream(flipped), geometry, fixed, checked, estimator, True)

        candidates = encoder_sign_candidates(loaded, geometry, settings)  # the rolling constraints tell first
        if candidates:
            raise pick_sign_candidate(loaded, candidates, refit) from None
        if isinstance(exc, UnidentifiableError):
            raise
        unchecked = refit(loaded, lenient.replace(max_relative_std=math.inf))
        cause, detail = diagnose_signs(loaded, refit, overall_rms(unchecked))
        raise ImplausibleError(exc.implausible, cause, detail) from None


class _LogStream:
    """The logs of one identification as ``(log, core)``, read one at a time (the first one already
    read); a long log in our schema comes in pieces (:func:`agvdyn.io.chunks.log_pieces`, ``core``
    its own rows), any other whole (``core`` None)."""

    def __init__(self, items: Sequence[Any], load: Any = None, first: Any = None, lifted: Any = None,
                 pieces: Any = None) -> None:
        self.items, self.load, self.first, self.lifted = list(items), load or (lambda x: x), first, lifted
        self.pieces = pieces

    def __iter__(self):
        for job in self.jobs():
            yield job()

    def jobs(self):
        """One callable per log (or piece of a long log) that reads it and returns ``(log, core)``;
        pieces are read here, in order (each needs its neighbour's rows), whole files by the callable."""
        for k, item in enumerate(self.items):
            if self.pieces is not None and not hasattr(item, "alpha") and self.pieces(item) is not None:
                for piece in self.pieces(item):
                    yield lambda piece=piece: piece
                continue
            yield functools.partial(self._whole, k, item)

    def _whole(self, k: int, item: Any) -> tuple[Any, None]:
        log = self.first if k == 0 and self.first is not None else self.load(item)
        if self.lifted is not None and self.lifted(log):
            from agvdyn.identification.lifted import lifted_experiment

            lifted_experiment([self.first, log], None)  # raises: lifted and vehicle logs mixed
        return log, None


def _reduced_logs(stream: _LogStream, geometry: Geometry, settings: IdentificationSettings, width: int,
                  order: np.ndarray, workers: int, reuse: bool) -> Iterator[tuple[Any, Any, Any, LogReduction]]:
    """``(log, core, rows, reduction)`` of every log of the stream, in order: read, filtered, rows
    classified and reduced (:func:`.normal.reduce_blocks`) in up to ``workers`` threads at a time
    (the compiled kernels, pyarrow and LAPACK release the GIL), at most ``workers + 1`` logs ahead.
    ``reuse``: the blocks are not wanted (``rows.blocks`` empty), each thread reuses its buffers."""

    local = threading.local()

    def work(job):
        log, core = job()
        space = None
        if reuse:  # the blocks are dropped once reduced: the next log of this thread reuses the buffers
            space = local.__dict__.setdefault("workspace", Workspace())
        rows = log_rows(log, geometry, settings, core, space)
        reduction = reduce_blocks(rows.blocks, width, offsets=settings.fit.torque_offsets, columns=order,
                                  workspace=space)
        if reuse:
            rows = dataclasses.replace(rows, blocks=())
        return log, core, rows, reduction

    yield from ordered_map(work, stream.jobs(), workers, "agvdyn-identify")


def _identify_stream(logs: _LogStream, geometry: Geometry, fixed: Mapping[str, float],
                     settings: IdentificationSettings, estimator: Estimator | None, keep_blocks: bool,
                     workers: int = 1) -> Identification:
    """Rows of each log reduced to normal equations as it is read (:mod:`.normal`), then one regression."""
    fixed = check_fixed(fixed)
    _, _, idx_free, p_fixed = columns(fixed, settings.fit.torque_offsets)
    order = np.array(list(idx_free) + [i for i in range(len(p_fixed)) if i not in idx_free])  # free columns first
    stats, store, names = RowStatistics(len(p_fixed), columns=order), RowStore(columns=order), {}
    blocks: list[EquationBlock] = []
    notes: list[str] = []
    counts = RowCounts()
    events: list[SlipEvent] = []
    thresholds: dict[str, float] = {}
    sources: list[str] = []
    labels: set[str] = set()
    n_samples = 0
    consumed = 0  # own rows of the earlier pieces of a long log: the sample index of this piece's first own row
    try:
        for log, core, rows, reduction in _reduced_logs(logs, geometry, settings, len(p_fixed), order, workers,
                                                        reuse=not keep_blocks):
            source = str(getattr(log, "path", None) or "<log>")
            if core is not None and (not sources or sources[-1] != source):
                consumed = 0
            offset = 0 if core is None else consumed - core.start  # piece steps -> the log's sample index
            merge_reduction(reduction, stats, store, names, step_offset=offset)
            if core is not None:
                consumed += core.stop - core.start
            if keep_blocks:
                blocks += rows.blocks
            notes += rows.notes
            counts.add(rows.counts)
            events += rows.slip_events
            thresholds[rows.source] = rows.slip_threshold
            if core is None or not sources or sources[-1] != source:  # pieces of one file: one source
                sources.append(source)
            labels |= labels_present(log)
            n_samples += rows.counts.samples
        _check_segments_present(labels, settings)
        if not stats.n_rows:
            raise ValueError(
                "no usable rows: the logs contain no samples in a motion mode of the model "
                f"(segments used: {', '.join(settings.rows.segments) if settings.rows.segments else 'all'}; "
                f"rows: {counts.to_dict()})")
        data = regression_data(stats, names, idx_free, p_fixed, store)
        return fit_regression(data, geometry, fixed=fixed, settings=settings, estimator=estimator, blocks=blocks,
                              sources=sources, notes=notes, n_samples=n_samples, rows=counts, slip_events=events,
                              slip_thresholds=thresholds, workers=workers)
    finally:
        store.close()


def _pieces_of(item: Any):
    """Pieces of a long log file in our schema (:func:`agvdyn.io.chunks.log_pieces`), None otherwise."""
    from agvdyn.io.chunks import is_long_log, log_pieces

    if hasattr(item, "alpha") or not is_long_log(item):
        return None
    return log_pieces(item)


def _check_segments_present(present: set[str], settings: IdentificationSettings) -> None:
    """``settings.rows.segments`` must name labels some log carries; else an error listing the ones present."""
    if settings.rows.segments is None:
        return
    missing = [s for s in settings.rows.segments if s not in present]
    if missing:
        raise ValueError(f"segments {missing} are not in the logs: the logs carry the labels "
                         f"{sorted(present) or 'none (no segment column)'}")
