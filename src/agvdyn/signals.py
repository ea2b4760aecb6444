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
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

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


class DerivativeScheme(str, Enum):
    """Finite-difference scheme of :func:`time_derivative`."""

    #: second-order central differences inside, second-order one-sided at the ends (np.gradient)
    CENTRAL = "central"


@dataclass(frozen=True)
class FilterSettings:
    """Zero-phase Butterworth low-pass used for every signal (paper sec. 7).

    Parameters
    ----------
    cutoff : float
        Cut-off angular frequency ``omega_g`` in rad/s (paper: 40 rad/s).
    order : int
        Order of the Butterworth prototype; the forward-backward pass doubles it.
    derivative : DerivativeScheme
        Finite-difference scheme applied after filtering.
    """

    cutoff: float = 40.0
    order: int = 4
    derivative: DerivativeScheme = DerivativeScheme.CENTRAL

    def __post_init__(self) -> None:
        if not isinstance(self.cutoff, (int, float)) or not math.isfinite(self.cutoff) or self.cutoff <= 0:
            raise ValueError(f"filter cutoff={self.cutoff!r} rad/s: expected a finite number > 0")
        if isinstance(self.order, bool) or not isinstance(self.order, int) or not 1 <= self.order <= 12:
            raise ValueError(f"filter order={self.order!r}: expected an integer in 1..12")
        object.__setattr__(self, "cutoff", float(self.cutoff))
        object.__setattr__(self, "derivative", DerivativeScheme(self.derivative))

    def sos(self, dt: float) -> np.ndarray:
        """Second-order sections of the digital Butterworth filter for sample time ``dt`` (s)."""
        nyquist = math.pi / dt  # rad/s
        if self.cutoff >= nyquist:
            raise ValueError(
                f"filter cutoff {self.cutoff} rad/s is not below the Nyquist frequency {nyquist:.6g} rad/s "
                f"of the sample time {dt} s"
            )
        return _design(self.order, self.cutoff / nyquist)[0].copy()

    def padlen(self, dt: float) -> int:
        """Number of samples ``sosfiltfilt`` pads at each end (its default for these sections)."""
        sos = self.sos(dt)
        return 3 * (2 * len(sos) + 1 - min((sos[:, 2] == 0).sum(), (sos[:, 5] == 0).sum()))


@functools.lru_cache(maxsize=64)
def _design(order: int, normalized_cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """Sections and ``sosfilt_zi`` of a Butterworth low-pass, designed once per order and cut-off
    (kept on disk: :mod:`agvdyn._filter_cache`)."""
    from agvdyn._filter_cache import butterworth_lowpass

    return butterworth_lowpass(order, normalized_cutoff)


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


def guarded_mask(keep: np.ndarray, guard: int, *, axis: int = 0) -> np.ndarray:
    """``keep`` with every row within ``guard`` samples of a dropped row (or of an end) dropped too.

    A zero-phase filter spreads each sample over about ``2 / omega_g`` on both sides, so rows next
    to the stiction rows carry what happens at low speed (stick/slip, wheel slip, the tanh
    transition) after filtering; this removes them. O(N) by cumulative sums.

    Examples
    --------
    >>> guarded_mask(np.array([True, True, True, False, True, True, True, True]), 1).tolist()
    [False, True, False, False, False, True, True, False]
    """
    keep = np.asarray(keep, dtype=bool)
    if guard < 0:
        raise ValueError(f"guard={guard!r}: expected >= 0 samples")
    if guard == 0:
        return keep.copy()
    moved = np.moveaxis(keep, axis, 0)
    n = moved.shape[0]
    bad = np.concatenate([np.ones((guard,) + moved.shape[1:], dtype=np.int64), (~moved).astype(np.int64),
                          np.ones((guard,) + moved.shape[1:], dtype=np.int64)])
    cs = np.concatenate([np.zeros((1,) + moved.shape[1:], dtype=np.int64), np.cumsum(bad, axis=0)])
    window = cs[2 * guard + 1: 2 * guard + 1 + n] - cs[:n]  # bad rows in [i - guard, i + guard]
    return np.moveaxis(window == 0, 0, axis)


#: Mode of each named experiment phase (PLATFORM.md, log column ``segment``). ``None``: excluded.
#: ``align`` (re-orienting the wheels at rest between two experiments) is physically mode 1, but
#: it is a short, rate-limited transition rather than a planned excitation; its rows sit next to
#: accelerating or braking phases where wheel slip is largest, so it is excluded from the
#: regression (pass ``segment_modes`` to include it).
SEGMENT_MODES: dict[str, str | None] = {
    "steer_left": "1",
    "steer_right": "1",
    "straight": "2s",
    "rotation": "4",
    "lateral": "3",
    "lane_change": "2",
    "align": None,
    "rest": None,
}
#: The paper's identification experiments, in their execution order (sec. 6.2).
IDENTIFICATION_SEGMENTS = ("steer_left", "steer_right", "straight", "rotation")


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
