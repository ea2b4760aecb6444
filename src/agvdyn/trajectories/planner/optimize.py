"""plan(): several starts of L-BFGS-B over all phases, the plan and its checks."""
from __future__ import annotations

import contextlib
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.optimize

from agvdyn.determinacy import std_from_information
from agvdyn.platform import PAPER_PARAMETERS, PROTOTYPE, SAMPLE_TIME, Geometry, Parameters
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import default_excitation
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.limits import FloorSpace, Limits, check_limits
from agvdyn.trajectories.segments import Trajectory
from agvdyn.trajectories.planner.evaluation import (
    _information,
    _row_variance,
    _sequence_rows,
    default_for_floor,
    evaluate_sequence,
)
from agvdyn.trajectories.planner.result import Candidate, PhaseDesign, Plan
from agvdyn.trajectories.planner.problem import _alignments, _Basis, _phase_models, _Problem, _sequence
from agvdyn.trajectories.planner.weights import _log_cond
from agvdyn.trajectories.planner.settings import PlanSettings, parse_floor

if TYPE_CHECKING:
    pass


def _worker(args) -> tuple[float, np.ndarray, list[int], dict[str, Any]]:
    problem_args, x0, k, iterations = args
    problem = _Problem(*problem_args)
    t0 = time.perf_counter()
    res = scipy.optimize.minimize(problem, x0, jac=True, method="L-BFGS-B",
                                  options={"maxiter": iterations, "maxcor": 20})
    msg = str(res.message)
    F, _, U, T, _, band = problem.information(res.x)
    info = {"start": k, "objective": float(res.fun), "iterations": int(res.nit),
            "harmonics": [b.H for b in problem.bases], "durations": [float(x) for x in T],
            "cond_smooth": float(np.exp(_log_cond(U)[0])), "penalty_share": float(band), "message": msg,
            "seconds": time.perf_counter() - t0}
    return float(res.fun), res.x, [b.H for b in problem.bases], info


def one_blas_thread(active: bool = True) -> Any:
    """A context in which the BLAS libraries of this process (and of processes forked in it) use one
    thread (``threadpoolctl``): worker processes that inherit all cores' BLAS threads each start that
    many on small matrix products (``agvdyn plan`` on two cores took 1.7-2x the wall time; docs/planning.md,
    "Stop 22, second helper"); the counts are restored on leaving. ``active`` False: nothing changes."""
    if not active:
        return contextlib.nullcontext()
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def _run_starts(jobs: list, settings: PlanSettings) -> list[tuple[float, np.ndarray, list[int], dict[str, Any]]]:
    """Every start for ``explore_iterations`` of L-BFGS-B, then the ``refine`` best ones on to
    ``max_iterations`` in all (the starts' objectives after the first iterations rank them well
    enough, and the iterations go where they pay)."""
    first = min(settings.explore_iterations, settings.max_iterations)
    rest = settings.max_iterations - first
    workers = settings.workers or min(2, os.cpu_count() or 1)
    pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs))) if workers > 1 and len(jobs) > 1 else None
    try:
        with one_blas_thread(pool is not None):  # inherited by the forked workers
            mapper = pool.map if pool is not None else map
            results = list(mapper(_worker, [(*job, first) for job in jobs]))
            order = sorted(range(len(results)), key=lambda i: results[i][0])[:settings.refine] if rest > 0 else []
            again = list(mapper(_worker, [(jobs[i][0], results[i][1], jobs[i][2], rest) for i in order]))
    finally:
        if pool is not None:
            pool.shutdown()
    for i, (fun, x, harmonics, info) in zip(order, again):
        before = results[i][3]
        info.update(iterations=before["iterations"] + info["iterations"], seconds=before["seconds"] + info["seconds"],
                    explore_objective=before["objective"])
        results[i] = (fun, x, harmonics, info)
    return results


def plan(geom: Geometry = PROTOTYPE, floor: FloorSpace | str = FloorSpace(5.2, 1.6), duration: float | None = None,
         *, params: Parameters = PAPER_PARAMETERS, limits: Limits = Limits(),
         settings: PlanSettings = PlanSettings(), dt: float = SAMPLE_TIME) -> Plan:
    """Optimal identification sequence (sec. 6.2) for ``geom`` in ``floor`` within ``duration`` s.

    ``duration`` None: the default sequence's (117.6 s on the prototype). ``params``: the nominal
    parameters for the feed-forward torques of the limit check (eq. 21) and the relative stds.
    Raises TrajectoryError when the floor cannot hold the vehicle's rotation or straight motion,
    or the duration is too short for the alignments and four phases.
    """
    t_start = time.perf_counter()
    floor = parse_floor(floor) if isinstance(floor, str) else floor
    rotation_width = math.hypot(geom.l, geom.b) + 2 * abs(geom.a)
    if floor.width < rotation_width - 1e-9 or floor.length < rotation_width - 1e-9:
        raise TrajectoryError(f"floor {floor.length:g} m x {floor.width:g} m: the pure rotation needs a "
                              f"{rotation_width:.3f} m x {rotation_width:.3f} m square (sqrt(l^2 + b^2) + 2a, sec. 6.2)")
    default_traj = default_for_floor(geom, None, None, limits, settings=settings, dt=dt)
    if duration is None:
        duration = default_traj.duration
    reference_traj = default_for_floor(geom, floor, duration, limits, settings=settings, dt=dt)
    reference = evaluate_sequence(reference_traj, params, limits, settings)
    models = _phase_models(geom, params, floor, limits, settings)
    aligns = _alignments(geom, settings, dt)
    align_time = sum(a.n_samples for a in aligns) * dt
    available = duration - align_time
    # constant information of the alignments (the identification uses their rows)
    A0, s0, q0 = _sequence_rows(Trajectory(tuple(aligns[:4]), geom, dt), settings, validity=True)
    A1, s1, q1 = _sequence_rows(Trajectory((aligns[4],), geom, dt), settings, validity=True)
    A0, s0, q0 = np.concatenate([A0, A1]), np.concatenate([s0, s1]), np.concatenate([q0, q1])
    F0, U0 = _information(A0, s0)
    F0 = F0 + 1e-12 * np.eye(F0.shape[0])
    O0 = _row_variance(A0, s0, q0) + 1e-12 * np.eye(F0.shape[0])
    ref_rows, ref_sig, ref_q = _sequence_rows(reference_traj, settings, validity=True)
    Fr, _ = _information(ref_rows, ref_sig)
    ref_std, _, _, _ = std_from_information(Fr, _row_variance(ref_rows, ref_sig, ref_q))
    ref_log = (np.log(ref_std[:10]) - np.log(np.abs(params.to_vector()[:10]))
               if np.all(np.isfinite(ref_std[:10])) else None)
    rng = np.random.default_rng(settings.seed)
    lo, hi = settings.harmonics
    jobs = []
    periods = list(settings.periods)
    base_share = np.array([24.0, 24.0, 30.0, 30.0]) * np.sqrt(periods)
    for k in range(settings.starts):
        share = base_share * np.exp(rng.normal(0, 0.3, 4))
        T0 = share / share.sum() * available
        harmonics = []
        for T, p in zip(T0, periods):
            cap = max(lo, int(settings.max_frequency * T / (2 * math.pi * p)))
            harmonics.append(int(rng.integers(lo, min(hi, cap) + 1)))
        t_min = np.array([max(settings.min_phase, 2 * math.pi * H * p / settings.max_frequency)
                          for H, p in zip(harmonics, periods)])
        if t_min.sum() >= available:
            harmonics = [lo] * 4
            t_min = np.array([max(settings.min_phase, 2 * math.pi * lo * p / settings.max_frequency) for p in periods])
        grid_points = [max(200, int(math.ceil(2 * T / settings.grid))) for T in T0]
        frac = np.clip((T0 - t_min) / max(available - t_min.sum(), 1e-9), 1e-3, None)
        eta0 = np.log(frac / frac.sum())
        if k % 2 == 0:  # the default excitation's shape on this phase's harmonics, perturbed
            thetas = [_default_shape(m.name, H, T, n_, p) * (1 + 0.2 * k / max(settings.starts, 1))
                      + 0.05 * k / max(settings.starts, 1) * rng.standard_normal(2 * H) / np.tile(np.arange(1, H + 1), 2)
                      for m, H, T, n_, p in zip(models, harmonics, T0, grid_points, periods)]
        else:
            thetas = [rng.standard_normal(2 * H) / np.tile(np.arange(1, H + 1), 2) for H in harmonics]
        x0 = np.concatenate([*thetas, eta0])
        problem_args = (models, harmonics, available, settings, params.to_vector(), F0, U0, ref_log, dt, grid_points, O0,
                        periods)
        jobs.append((problem_args, x0, k))
    results = _run_starts(jobs, settings)
    order = sorted(range(len(results)), key=lambda i: results[i][0])
    candidates = []
    for rank, i in enumerate(order[:settings.candidates]):  # the best starts, built and evaluated exactly
        traj, phases = _build(_Problem(*jobs[i][0]), results[i][1], geom, params, limits, settings, dt)
        candidates.append(Candidate(results[i][3]["start"], rank, float(results[i][0]), traj, phases,
                                    evaluate_sequence(traj, params, limits, settings)))
    best = candidates[0]
    return Plan(best.trajectory, best.phases, floor, best.evaluation, reference, reference_traj, settings.objective,
                best.objective_value, tuple(r[3] for r in results), time.perf_counter() - t_start, params, settings,
                limits, tuple(candidates))


_LIMITING = ("velocity", "acceleration", "excursion", "motor torque")


def _default_shape(name: str, H: int, T: float, n: int, periods: int = 1) -> np.ndarray:
    """Coefficients (2H,) on the basis of a phase of duration T whose velocity is closest (least
    squares) to the default excitation of that phase repeated over T (a start of the optimiser)."""
    series = default_excitation(name)
    B = _Basis.of(H, n, periods)
    t = (np.arange(n) + 0.5) / n * T
    _, v, _ = series.evaluate(t % series.period)
    coef, *_ = np.linalg.lstsq(B.Cv, v / max(np.max(np.abs(v)), 1e-12), rcond=None)
    return B.Pi @ coef


def _build(problem: _Problem, x: np.ndarray, geom: Geometry, params: Parameters, limits: Limits,
           settings: PlanSettings, dt: float) -> tuple[Trajectory, tuple[PhaseDesign, ...]]:
    """The planned trajectory at T_s; a phase whose peaks between grid points break a limit is scaled down."""
    thetas, eta = problem.split(x)
    T = problem.durations(eta)
    series, designs, scales = {}, [], {}
    for j, m in enumerate(problem.models):
        B = problem.bases[j]
        n = max(1, int(round(T[j] / dt)))
        c = B.Pi @ thetas[j]
        s, kind, _, _ = problem.scale(j, c, T[j])
        scales[m.name] = (c, s, kind, n * dt, B.H)
    for _ in range(5):
        series = {}
        for name, (c, s, kind, Tp, H) in scales.items():
            p = problem.bases[[mm.name for mm in problem.models].index(name)].periods
            # velocity amplitudes of the basis on u = t / T are the same on t; with p periods the
            # harmonics p, 2p, ... of the phase (the others zero)
            a, b = np.zeros(H * p), np.zeros(H * p)
            a[p - 1::p], b[p - 1::p] = s * c[:H], s * c[H:]
            series[name] = FourierSeries(2 * math.pi / Tp, tuple(a), tuple(b))
        traj = _sequence(geom, series, settings, dt)
        shrink = _violations(traj, params, limits, problem)
        if not shrink:
            break
        for name, f in shrink.items():
            c, s, kind, Tp, H = scales[name]
            scales[name] = (c, s * f, kind, Tp, H)
    check_limits(traj, params, limits)
    for name, (c, s, kind, Tp, H) in scales.items():
        seg = next(sg for sg in traj.segments if sg.name == name)
        col = 1 if name == "steer_right" else 0
        m = next(mm for mm in problem.models if mm.name == name)
        designs.append(PhaseDesign(
            name=name, mode=m.mode.label, coordinate=m.coordinate, duration=seg.duration + dt, harmonics=H,
            series=series[name], peak_position=float(np.max(np.abs(seg.s[:, col]))),
            peak_velocity=float(np.max(np.abs(seg.s_dot[:, col]))),
            peak_acceleration=float(np.max(np.abs(seg.s_ddot[:, col]))), limiting=_LIMITING[kind]))
    return traj, tuple(designs)


def _violations(traj: Trajectory, params: Parameters, limits: Limits, problem: _Problem) -> dict[str, float]:
    """Per phase, the factor that brings its peaks within the plan's limits (empty: all within)."""
    out = {}
    qd, qdd = traj.joint_motion()
    u = traj.feedforward(params)
    for (name, sl), seg in zip(traj.segment_slices(), traj.segments):
        m = next((mm for mm in problem.models if mm.name == name), None)
        if m is None:
            continue
        col = 1 if name == "steer_right" else 0
        ratios = [m.v_limit / max(np.max(np.abs(seg.s_dot[:, col])), 1e-12),
                  m.a_limit / max(np.max(np.abs(seg.s_ddot[:, col])), 1e-12),
                  m.q_limit / max(np.max(np.abs(seg.s[:, col])), 1e-12)]
        y = np.abs(u[sl]).max()
        if y > m.torque_limit:
            ratios.append(m.torque_limit / y)
        f = min(ratios)
        if f < 1.0:
            out[name] = 0.995 * f
    return out


# --- figure ----------------------------------------------------------------------------------------
