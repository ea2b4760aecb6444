"""Stage 1 of the row pipeline: continuous stretches of a log, each filtered once (sec. 7).

A log is cut only where the recording is not continuous: a time step longer than a few nominal
steps (a dropout) or an angle step no vehicle can make (two recordings joined, an encoder
reset). Each stretch is low-passed and differentiated once, as a whole; odometry (eq. 3) and the
entries of Theta (eq. 16) are computed on the filtered signals, the slip speed of the redundant
rolling constraints on lighter filtered steering rates and raw wheel rates (``slip_cutoff``), and
in PARALLEL filtering the entries of Theta and the torques are low-passed once more together (in
MATCHED filtering the torques and the friction entries pass the angles' filter first, so that every
entry of both sides sees two filters: :func:`matched_prefilter`).
Segment labels, motion modes, stiction and slip are decided
afterwards, row by row, on these filtered signals: no filter ever starts or ends at a label.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from agvdyn._zero_phase import filtfilt_in_place
from agvdyn.identification._kernels import SIGNAL_CHANNELS, copy_rows, recording_breaks, stretch_motion
from agvdyn.identification.model_rows import fill_model_channels, model_channels, stretch_torque
from agvdyn.identification.settings import Filtering, IdentificationSettings
from agvdyn.identification.workspace import Workspace, empty
from agvdyn.model_spec import PAPER_MODEL, ModelSpec
from agvdyn.platform import Geometry
from agvdyn.signals import FilterSettings, filter_design, lowpass, uniform_sample_time
from agvdyn.time_base import stamp_interval

__all__ = ["Stretch", "stretch_bounds", "stretches_of", "filtered_stretch", "log_source", "edge_rows", "min_stretch_rows",
           "torque_lead", "align_torque", "slip_filter", "matched_prefilter", "MATCHED_COLUMNS"]


def log_source(log: Any) -> str:
    return str(getattr(log, "path", None) or "<log>")


@dataclass(frozen=True, eq=False)
class Stretch:
    """One continuous stretch of a log, filtered once; arrays have the stretch's rows first.

    ``rows``: the rows of the log. ``alpha`` (n, 2) filtered steering angles (clipped to the
    stops); ``q_dot``, ``q_ddot`` (n, 9) joint velocities and accelerations (the latter formed
    on demand), the chassis ones by odometry (eq. 3), the others derivatives of the filtered
    angles (views: ``alpha_dot``, ``beta_dot``, ``chassis_dot``, ...); ``slip`` (n, 4) slip speed per wheel (m/s);
    ``signals`` (n, 21) entries of Theta (:data:`agvdyn.dynamics.REGRESSOR_SIGNALS`) and
    ``torque`` (n, 4) motor torques, both filtered alike in PARALLEL filtering (the torques and the
    friction entries twice in MATCHED); ``edge`` (n,) rows within the filter's transient of either
    end (and, with a torque delay, rows whose shifted torque falls outside the stretch); ``trig``
    (n, 4) sin and cos of the left and right steering angle; ``extra`` (n, q) the model extensions' channels (:mod:`.model_rows`; q = 0 for the paper's).
    """

    source: str
    rows: slice
    t: np.ndarray
    dt: float
    alpha: np.ndarray
    q_dot: np.ndarray
    slip: np.ndarray
    signals: np.ndarray
    torque: np.ndarray
    edge: np.ndarray
    trig: np.ndarray
    extra: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.t.size

    @property
    def chassis_dot(self) -> np.ndarray:
        return self.q_dot[:, :3]

    @property
    def alpha_dot(self) -> np.ndarray:
        return self.q_dot[:, 3:5]

    @property
    def beta_dot(self) -> np.ndarray:
        return self.q_dot[:, 5:]

    @property
    def q_ddot(self) -> np.ndarray:
        """Joint accelerations (n, 9): derivatives of ``q_dot`` as in the signals (``np.gradient``,
        second order at the ends), formed when asked for (the row pipeline does not keep them)."""
        return np.gradient(self.q_dot, self.dt, axis=0, edge_order=2)

    @property
    def chassis_ddot(self) -> np.ndarray:
        return self.q_ddot[:, :3]

    @property
    def alpha_ddot(self) -> np.ndarray:
        return self.q_ddot[:, 3:5]

    @property
    def beta_ddot(self) -> np.ndarray:
        return self.q_ddot[:, 5:]


def torque_lead(log: Any, settings: IdentificationSettings) -> float:
    """Samples by which a log's torques lead its angles: ``settings.rows.torque_lead``, else the sidecar's
    ``torque_lead`` (``agvdyn.simulation`` writes 0.5), else 0."""
    if settings.rows.torque_lead is not None:
        return float(settings.rows.torque_lead)
    from agvdyn.io.log import sidecar_value

    value = sidecar_value(log, "torque_lead")
    if value is None:
        return 0.0
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
        raise ValueError(f"{log_source(log)}: sidecar torque_lead={value!r}: expected a number of samples in [0, 1]")
    return float(value)


def align_torque(torque: np.ndarray, lead: float) -> np.ndarray:
    """Torques at the instants of the angle samples: ``(1 - lead) m[k] + lead m[k - 1]`` (first row kept).

    A zero-order-hold drive applies the torque logged in row k from t_k to t_k + T_s; around t_k
    it acts as the mean of the held values before and after, ``(m[k - 1] + m[k]) / 2`` (lead 0.5).
    """
    if lead == 0 or torque.shape[0] < 2:
        return torque
    out = torque.copy()
    out[1:] = (1.0 - lead) * torque[1:] + lead * torque[:-1]
    return out


def edge_rows(settings: IdentificationSettings, dt: float) -> int:
    """Rows dropped at each end of a stretch: the filter's transient."""
    return int(math.ceil(settings.rows.seconds(settings.rows.edge_guard) / dt))


def min_stretch_rows(settings: IdentificationSettings, dt: float) -> int:
    """Fewest rows a stretch needs: more than the filter's padding and both edges."""
    return max(settings.rows.filter.padlen(dt), 2 * edge_rows(settings, dt)) + 1


def stretch_bounds(t: np.ndarray, alpha: np.ndarray, beta: np.ndarray, settings: IdentificationSettings
                   ) -> tuple[list[tuple[int, int]], list[str]]:
    """Half-open row ranges of the continuous stretches of a log, and why each cut was made."""
    bounds, reasons, _ = stretches_of(t, alpha, beta, settings)
    return bounds, reasons


def stretches_of(t: np.ndarray, alpha: np.ndarray, beta: np.ndarray, settings: IdentificationSettings,
                 nominal: float | None = None) -> tuple[list[tuple[int, int]], list[str], float]:
    """:func:`stretch_bounds` and the nominal time step of the log (:func:`agvdyn.time_base.stamp_interval`; NaN for one sample;
    ``nominal`` when it is already known)."""
    if t.size < 2:
        return [(0, t.size)], [], math.nan
    nominal = stamp_interval(t, source="column 't'") if nominal is None else float(nominal)
    kind = np.empty(t.size - 1, dtype=np.int8)
    rules = settings.rows
    found = recording_breaks(t, alpha, beta, rules.stretch_gap * nominal, rules.steering_jump_rate * nominal,
                             rules.wheel_jump_rate * nominal, kind)
    cuts = np.flatnonzero(kind) if found else np.zeros(0, dtype=np.int64)
    reasons = []
    for i in cuts:
        what = (f"a dropout of {t[i + 1] - t[i]:.4g} s" if kind[i] == 1 else
                "a steering angle jump" if kind[i] == 2 else "a wheel angle jump")
        reasons.append(f"cut between t = {t[i]:.6g} s and {t[i + 1]:.6g} s: {what}")
    starts = np.concatenate([[0], cuts + 1])
    stops = np.concatenate([cuts + 1, [t.size]])
    return list(zip(starts.tolist(), stops.tolist())), reasons, nominal


def slip_filter(settings: IdentificationSettings, dt: float) -> FilterSettings:
    """Low-pass of the steering angles whose rates enter the slip speed: ``slip_cutoff``, at most
    0.8 x the Nyquist frequency of ``dt``, the regression filter's order."""
    rules = settings.rows
    return FilterSettings(cutoff=min(rules.slip_cutoff, 0.8 * math.pi / dt), order=rules.filter.order)


#: Columns of the second filter's buffer that MATCHED filtering low-passes once more first: the six
#: friction entries ``tanh(q_dot / epsilon)`` (functions of once-filtered rates; the order of
#: :data:`agvdyn.dynamics.REGRESSOR_SIGNALS`) and the four torques; the model's channels follow them.
MATCHED_COLUMNS = np.array([5, 8, 17, 18, 19, 20, 21, 22, 23, 24])


def matched_prefilter(middle: np.ndarray, design: tuple[np.ndarray, np.ndarray, int],
                      workspace: Workspace | None = None, tag: str = "") -> None:
    """MATCHED filtering, in place on the channels (n, 25 + q) of the second filter: the torques, the
    friction entries and the model's channels through the angles' low-pass ``design`` (sections,
    initial state, padding) once, so that every entry of both sides of eq. (19) sees two filters.

    The accelerations and rates are derivatives of filtered angles (one filter) and pass the second;
    a function of a once-filtered rate (``tanh``, ``e tanh``, ``gamma_dot^2``) stands for the function
    of the rate itself filtered once (exact where the rate changes slowly against the filter), and so
    needs one more, as the torques do. PARALLEL leaves torques and friction entries at one filter
    against two for the inertia terms: at a breakaway, where the acceleration jumps, that is
    ``C (F a - F F a)``, several N m for ~100 ms."""
    sos, zi, pad = design
    n = middle.shape[0]
    columns = np.concatenate([MATCHED_COLUMNS, np.arange(SIGNAL_CHANNELS, middle.shape[1])])
    buffer = empty(workspace, f"matched{tag}", (n + 2 * pad, columns.size))
    buffer[pad:pad + n] = middle[:, columns]
    middle[:, columns] = filtfilt_in_place(sos, zi, buffer, pad)


def filtered_stretch(geometry: Geometry, log: Any, start: int, stop: int, settings: IdentificationSettings,
                     workspace: Workspace | None = None, tag: str = "", median_step: float | None = None,
                     model: ModelSpec = PAPER_MODEL) -> Stretch:
    """Filter, differentiate and evaluate one stretch ``[start, stop)`` of a log once.

    The angles are low-passed in one compiled pass (the steering angles once more through the
    lighter slip filter), then :func:`._kernels.stretch_motion` takes derivatives, odometry (eq. 3),
    slip speeds, the entries of Theta and the aligned torques in one pass, written straight into
    the buffer of the second filter (PARALLEL: all 25 channels, and the channels a resolved
    ``model`` adds, :mod:`.model_rows`; its delay reads the torques later).

    ``workspace``: buffers reused from the previous log (``tag`` tells this stretch's apart from
    the log's others); the arrays are then valid until the next log. ``median_step``: the median
    time step of the stretch when it is already known.

    Raises ValueError (naming source and rows) when the stretch is not uniformly sampled or is
    too short for the zero-phase filter.
    """
    source = log_source(log)
    sl = slice(start, stop)
    t = np.asarray(log.t[sl], dtype=float)
    where = f"{source}: rows {start}..{stop - 1} (t = {t[0]:.6g}..{t[-1]:.6g} s)"
    dt = uniform_sample_time(t, rtol=settings.rows.sample_jitter, source=f"{where}: column 't'", median=median_step)
    n = t.size
    sos, zi, pad = filter_design(dt, settings.rows.filter)
    if n <= pad:
        raise ValueError(f"{where}: signal of {n} samples is too short for the zero-phase filter: needs more than {pad}")
    angles = empty(workspace, f"angles{tag}", (n + 2 * pad, 6))
    copy_rows(angles[pad:pad + n, :2], log.alpha[sl])
    copy_rows(angles[pad:pad + n, 2:], log.beta[sl])
    f = filtfilt_in_place(sos, zi, angles, pad)
    fast_sos, fast_zi, fast_pad = filter_design(dt, slip_filter(settings, dt))
    fast = empty(workspace, f"fast{tag}", (n + 2 * fast_pad, 2))
    copy_rows(fast[fast_pad:fast_pad + n], log.alpha[sl])
    fast = filtfilt_in_place(fast_sos, fast_zi, fast, fast_pad)
    alpha, trig = empty(workspace, f"alpha{tag}", (n, 2)), empty(workspace, f"trig{tag}", (n, 4))
    slip, tanh = empty(workspace, f"slip{tag}", (n, 4)), empty(workspace, f"tanh{tag}", (n, 6))
    q_dot = empty(workspace, f"q_dot{tag}", (n, 9))
    both = empty(workspace, f"signals{tag}", (n + 2 * pad, SIGNAL_CHANNELS + model_channels(model)))
    middle = both[pad:pad + n]
    # a view of the log's columns (the kernel reads it strided), or the torques the model's delay reads
    torque, late_front, late_back = stretch_torque(np.asarray(log.torque[sl], dtype=float), model, dt)
    wheels = empty(workspace, f"wheels{tag}", (n, 4))  # raw: the slip's wheel rates (encoders resolve 1e-4 rad)
    copy_rows(wheels, log.beta[sl])
    stretch_motion(f, fast, wheels, dt, geometry.l, geometry.b, geometry.a, geometry.r, float(settings.rows.epsilon),
                   torque, torque_lead(log, settings), alpha, trig, q_dot, slip, middle, tanh)
    if not model.is_paper:
        fill_model_channels(model, q_dot, tanh, middle[:, SIGNAL_CHANNELS:])
    if settings.rows.filtering is Filtering.MATCHED:
        matched_prefilter(middle, (sos, zi, pad), workspace, tag)
    if settings.rows.filtering is not Filtering.LITERAL:  # PARALLEL, MATCHED: the second filter on every channel
        filtfilt_in_place(sos, zi, both, pad)
    else:
        middle[:, 21:SIGNAL_CHANNELS] = lowpass(middle[:, 21:SIGNAL_CHANNELS], dt, settings.rows.filter)
    k = edge_rows(settings, dt)
    edge = np.zeros(n, dtype=bool)
    edge[:k + late_front] = True
    edge[max(n - k - late_back, 0):] = True
    return Stretch(source, sl, t, dt, alpha, q_dot, slip, middle[:, :21], middle[:, 21:SIGNAL_CHANNELS], edge, trig,
                   middle[:, SIGNAL_CHANNELS:])
