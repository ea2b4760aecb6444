"""Signal processing for identification: zero-phase filters, time derivatives, stiction masks, modes.

The paper (sec. 7) filters every measured signal with a zero-phase low-pass of cut-off
``omega_g = 40 rad/s``, "including those for first and second order time derivatives", and
sets a row of the equation system to zero when its generalized velocity is below a threshold.

Design
------
* :func:`lowpass` is a Butterworth filter applied forward and backward
  (:func:`scipy.signal.sosfiltfilt`): zero phase, magnitude ``|H(j omega)|^2`` of the
  Butterworth prototype, i.e. ``1/2`` (-6 dB) at the cut-off.
* :func:`filtered_derivatives` filters first and then differentiates with second-order
  central differences (:func:`time_derivative`). Filter and differentiation are both linear
  and time invariant, so away from the ends ``D F x = F D x``: the derivative of the filtered
  angle *is* the filtered derivative, with the same (zero) phase as the filtered torques.
* :func:`parallel_filter` applies the same zero-phase filter to both sides of a linear
  equation ``Phi p = y`` (regressor columns and torques), run by run.

All functions take arrays with time along ``axis`` (default 0, the project's convention).
:class:`FilterSettings`, :class:`DerivativeScheme` and :func:`guarded_mask` live in the low module
:mod:`agvdyn.row_rules` (the planner shares them) and are re-exported here.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from agvdyn.segments_vocabulary import IDENTIFICATION_SEGMENTS, VOCABULARY
from agvdyn.row_rules import DerivativeScheme, FilterSettings, _design, guarded_mask
from agvdyn.time_base import stamp_interval

__all__ = [
    "FilterSettings",
    "DerivativeScheme",
    "lowpass",
    "time_derivative",
    "filtered_derivatives",
    "parallel_filter",
    "runs",
    "row_max_abs",
    "stiction_mask",
    "guarded_mask",
    "SEGMENT_MODES",
    "IDENTIFICATION_SEGMENTS",
    "modes_from_segments",
    "uniform_sample_time",
    "filter_design",
]


def filter_design(dt: float, settings: FilterSettings = FilterSettings()) -> tuple[np.ndarray, np.ndarray, int]:
    """Sections, ``sosfilt_zi`` and padding (samples per end) of the zero-phase filter for sample
    time ``dt``, designed once per order, cut-off and sample time (read only)."""
    settings.sos(dt)  # checks the cut-off against the Nyquist frequency
    sos, zi = _design(settings.order, settings.cutoff / (math.pi / dt))
    return sos, zi, _padlen(settings.order, settings.cutoff / (math.pi / dt))


@functools.lru_cache(maxsize=64)
def _padlen(order: int, normalized_cutoff: float) -> int:
    sos = _design(order, normalized_cutoff)[0]
    return 3 * (2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum()))


def uniform_sample_time(t: np.ndarray, *, rtol: float = 1e-3, source: str = "t", median: float | None = None) -> float:
    """Sample time of a uniformly sampled time vector (:func:`agvdyn.time_base.stamp_interval`);
    ``ValueError`` naming the first bad row otherwise. ``median``: the nominal time step when it is
    already known (the name is kept for callers)."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"{source}: expected a 1-D time vector with at least 3 samples, got shape {t.shape}")
    steps = np.diff(t)
    if median is None and not (steps > 0).all():
        row = int(np.argmax(steps <= 0)) + 1
        raise ValueError(f"{source}: row {row}: time step {steps[row - 1]:.6g} s, expected > 0 (strictly increasing time)")
    dt = stamp_interval(t, source=source) if median is None else float(median)
    if not dt > 0:
        raise ValueError(f"{source}: nominal time step {dt} s, expected > 0 (strictly increasing time)")
    bad = np.flatnonzero(np.abs(steps - dt) > rtol * dt)
    if bad.size:
        row = int(bad[0]) + 1
        raise ValueError(
            f"{source}: non-uniform sampling at row {row}: step {steps[row - 1]:.6g} s, expected {dt:.6g} s "
            f"(relative tolerance {rtol}); resample the log first"
        )
    return dt


def lowpass(x: np.ndarray, dt: float, settings: FilterSettings = FilterSettings(), *, axis: int = 0) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` along ``axis`` (forward-backward, ``sosfiltfilt``).

    Parameters
    ----------
    x : array_like
        Signal(s), time along ``axis``.
    dt : float
        Sample time in s.
    settings : FilterSettings
        Cut-off (rad/s) and order.

    Returns
    -------
    ndarray
        Filtered signal, same shape; no phase lag.

    Examples
    --------
    >>> t = np.arange(0, 4, 2e-3)
    >>> y = lowpass(np.sin(2 * t), 2e-3)
    >>> bool(np.max(np.abs(y - np.sin(2 * t))[500:-500]) < 1e-3)
    True
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[axis]
    padlen = settings.padlen(dt)
    if n <= padlen:
        raise ValueError(f"signal of {n} samples is too short for the zero-phase filter: needs more than {padlen}")
    if x.ndim in (1, 2) and axis in (0, -x.ndim):  # all channels in one compiled pass (same result)
        from agvdyn._zero_phase import sosfiltfilt_columns

        sos, zi = _design(settings.order, settings.cutoff / (math.pi / dt))
        return sosfiltfilt_columns(sos, zi, x.reshape(n, -1), padlen).reshape(x.shape)
    from scipy import signal

    return signal.sosfiltfilt(settings.sos(dt), x, axis=axis)


def time_derivative(x: np.ndarray, dt: float, *, axis: int = 0,
                    scheme: DerivativeScheme = DerivativeScheme.CENTRAL) -> np.ndarray:
    """First time derivative by second-order finite differences (error O(dt^2), also at the ends)."""
    scheme = DerivativeScheme(scheme)
    return np.gradient(np.asarray(x, dtype=float), dt, axis=axis, edge_order=2)


def filtered_derivatives(x: np.ndarray, dt: float, settings: FilterSettings = FilterSettings(), *,
                         axis: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Filtered signal and its first and second time derivatives ``(F x, D F x, D D F x)``.

    Filtering first and differentiating the smooth result is the same linear time-invariant
    operation as differentiating first and filtering, so all three outputs have zero phase
    lag and stay consistent with each other and with torques filtered by :func:`lowpass`.
    """
    xf = lowpass(x, dt, settings, axis=axis)
    xd = time_derivative(xf, dt, axis=axis, scheme=settings.derivative)
    xdd = time_derivative(xd, dt, axis=axis, scheme=settings.derivative)
    return xf, xd, xdd


def row_max_abs(x: np.ndarray) -> np.ndarray:
    """``max_j |x[:, j]|`` per row ``(N,)``, column by column (numpy's ``max(axis=1)`` over a few
    columns is ~15x slower: it reduces each short row on its own)."""
    x = np.asarray(x, dtype=float)
    out = np.abs(x[:, 0])
    for j in range(1, x.shape[1]):
        np.maximum(out, np.abs(x[:, j]), out=out)
    return out


def runs(labels: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges ``[start, stop)`` of consecutive equal entries of a 1-D array."""
    labels = np.asarray(labels)
    if labels.size == 0:
        return []
    change = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [labels.size]))
    return list(zip(starts.tolist(), stops.tolist()))


def parallel_filter(x: np.ndarray, dt: float, settings: FilterSettings = FilterSettings(),
                    bounds: list[tuple[int, int]] | None = None, *, axis: int = 0) -> np.ndarray:
    """The same zero-phase low-pass applied to every column, separately inside each run.

    Used on both sides of ``H_k^T Theta p = H_k^T B u`` (eq. 19) so that the sharp tanh
    Coulomb columns are smeared exactly like the measured torques ("parallel filtering").
    Columns that are identically zero in a run are left untouched (they stay zero).

    Parameters
    ----------
    bounds : list of (start, stop), optional
        Runs along ``axis`` filtered independently (a mode change is a break in the
        equation); default: the whole array is one run.
    """
    x = np.asarray(x, dtype=float)
    moved = np.moveaxis(x, axis, 0)
    out = moved.copy()
    n = moved.shape[0]
    flat = out.reshape(n, -1)
    from scipy import signal

    sos = settings.sos(dt)
    for start, stop in bounds if bounds is not None else [(0, n)]:
        block = flat[start:stop]
        active = np.flatnonzero(np.any(block != 0.0, axis=0))
        if active.size:
            flat[start:stop, active] = signal.sosfiltfilt(sos, block[:, active], axis=0)
    return np.moveaxis(flat.reshape(moved.shape), 0, axis)


def stiction_mask(s_dot: np.ndarray, threshold: float | np.ndarray) -> np.ndarray:
    """Rows of eq. (19) to drop: ``|s_dot_k,i| < threshold`` per generalized coordinate (sec. 7).

    Returns a boolean array of the shape of ``s_dot`` that is True where the row is kept.
    """
    s_dot = np.asarray(s_dot, dtype=float)
    threshold = np.asarray(threshold, dtype=float)
    if np.any(threshold < 0) or not np.all(np.isfinite(threshold)):
        raise ValueError(f"stiction threshold {threshold}: expected finite values >= 0")
    return np.abs(s_dot) >= threshold


#: Mode of each named experiment phase (PLATFORM.md, log column ``segment``;
#: :mod:`agvdyn.segments_vocabulary`). ``None``: excluded. ``align`` (re-orienting the wheels at rest
#: between two experiments) is physically mode 1, but it is a short, rate-limited transition rather
#: than a planned excitation; its rows sit next to accelerating or braking phases where wheel slip
#: is largest, so it is excluded from the regression (pass ``segment_modes`` to include it), as are
#: the lifted-wheel test and ``rest`` (rows at standstill; a name of raw arrays, not of the log schema).
SEGMENT_MODES: dict[str, str | None] = {
    **{s.name: s.mode if s.regression else None for s in VOCABULARY},
    "rest": None,
}


def modes_from_segments(segment: np.ndarray, *, segment_modes: dict[str, str | None] | None = None,
                        source: str = "segment") -> np.ndarray:
    """Mode label per row (``"1"``, ``"2"``, ``"2s"``, ``"3"``, ``"4"`` or ``""`` when excluded).

    Raises ``ValueError`` naming the first row of an unknown segment name.
    """
    table = SEGMENT_MODES if segment_modes is None else segment_modes
    segment = np.asarray(segment, dtype=object)
    names, inverse = np.unique(segment.astype(str), return_inverse=True)
    unknown = [n for n in names if n not in table]
    if unknown:
        row = int(np.flatnonzero(segment.astype(str) == unknown[0])[0])
        raise ValueError(
            f"{source}: unknown segment name {unknown[0]!r} (first at row {row}); expected one of {sorted(table)}"
        )
    labels = np.array([table[n] or "" for n in names], dtype=object)
    return labels[inverse]
