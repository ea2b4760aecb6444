"""Study: the payload tracker's acceptance figures (issue 31) on our plant or MuJoCo; prints the acceptance table.

    nice .venv/bin/python benchmarks/study_tracking.py [--seeds 20] [--first-seed 1] [--free-hours 2]
                                                       [--engine ours|mujoco] [--markdown] [--json runs.json]
                                                       [--free-first-seed 101]

``--engine mujoco``: the same runs on the MuJoCo plant (the vehicle generated from the prototype and
Table 2; the load a body welded to the chassis, simulation/mujoco_payload.py); the tracker holds the
MuJoCo vehicle's lumped parameters (equal to Table 2 to rounding).

1. Step study: ``seeds`` runs of ``driving`` (160 s, seed s) with one centred pick-up of +10..+60 %
   of m_ch (a pallet: yaw inertia ``m (1.2^2 + 0.8^2) / 12``, so C_ch grows by +5..+30 %) at a random
   time in 40-100 s (both drawn with ``numpy.random.default_rng(seed)``), replayed through
   :func:`agvdyn.online.track` with Table 2's parameters held. Per run:

   * the first *excited motion* after the step: the first sample at or after it at which the planned
     chassis acceleration reaches ``--accel`` m/s^2 in a translation mode (it shows m_ch) or
     ``--yaw-accel`` rad/s^2 in rotation (it shows C_ch);
   * detection: the first alarm after the step (an alarm of either parameter is a payload change:
     the tracker then re-estimates both); latency: its time (when the row that crossed the threshold
     was complete) less the first excited motion's;
   * m_ch and C_ch errors 3 s after the detection, and 3 s after the detection or the first motion
     that shows the parameter, whichever is later (a parameter cannot be known before it is excited);
   * the feed-forward's motor torques of eq. (21) on the planned motion from the step to the end, with
     the tracked parameters (the estimate available at each sample: rows are complete ``latency``
     late) and with the stale ones, against those with the true parameters: RMS over the four motors
     and the samples.

2. False alarms: ``driving`` without a step, ``free-hours`` h in runs of 600 s (seeds 101, 102, ...;
   ``--free-first-seed 201`` for the second set),
   plus the step runs before their step; alarms per hour.
"""
from __future__ import annotations

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, replace  # noqa: E402

import numpy as np  # noqa: E402

from agvdyn.io.log import Log  # noqa: E402
from agvdyn.kinematics import Mode  # noqa: E402
from agvdyn.online import TrackerSettings, TrackResult, track  # noqa: E402
from agvdyn.platform import PAPER_PARAMETERS as P, PROTOTYPE  # noqa: E402
from agvdyn.simulation import SimulationSettings, simulate  # noqa: E402
from agvdyn.simulation.payload import PayloadEvent  # noqa: E402
from agvdyn.trajectories import Trajectory, experiment  # noqa: E402

#: Pallet footprint (m) of the yaw inertia of a centred load: m (L^2 + W^2) / 12.
PALLET = (1.2, 0.8)
STEP_DURATION = 160.0
FREE_DURATION = 600.0
#: Goals of issue 31: latency (s), m_ch and C_ch error 3 s after detection (%), false alarms per hour.
GOALS = {"latency": 1.0, "m_ch": 2.0, "C_ch": 5.0, "false_per_hour": 1.0}


@dataclass(frozen=True)
class Case:
    """One run of the step study: the drawn step and the simulated log, its plan and true values."""

    seed: int
    step: PayloadEvent
    log: Log
    trajectory: Trajectory
    t_applied: float
    truth: np.ndarray  # (m_ch, C_ch) after the step


def step_of_seed(seed: int) -> PayloadEvent:
    """The seed's pick-up: +10..+60 % of m_ch at 40..100 s, centred, a pallet's yaw inertia."""
    rng = np.random.default_rng(seed)
    mass = float(rng.uniform(0.1, 0.6)) * P.m_ch
    return PayloadEvent(float(rng.uniform(40.0, 100.0)), mass, 0.0, 0.0, mass * (PALLET[0] ** 2 + PALLET[1] ** 2) / 12)


def simulated_log(traj: Trajectory, payload: tuple[PayloadEvent, ...], seed: int, engine: str = "ours"):
    """The run's log in memory (as read from its file) and the simulation result (on ``engine``)."""
    res = simulate(traj, settings=SimulationSettings(payload=payload), seed=seed, engine=engine)
    return Log.from_frame(res.log_frame(), sidecar=res.sidecar()), res


def step_case(seed: int, engine: str = "ours") -> Case:
    step = step_of_seed(seed)
    traj = experiment("driving", duration=STEP_DURATION, seed=seed)
    log, res = simulated_log(traj, (step,), seed, engine)
    truth = res.payload_truth[0]
    return Case(seed, step, log, traj, truth.t_applied, np.array([truth.m_ch, truth.C_ch]))


def first_excited(traj: Trajectory, t0: float, accel: float, yaw_accel: float) -> tuple[float, float]:
    """Times of the first planned translation acceleration >= ``accel`` and yaw acceleration >=
    ``yaw_accel`` (rotation mode) at or after ``t0`` (inf: none)."""
    _, qdd = traj.joint_motion()
    after = traj.t >= t0
    translate = np.isin(traj.mode, [int(Mode.STRAIGHT), int(Mode.CAR_LIKE), int(Mode.LATERAL)])
    rotate = traj.mode == int(Mode.ROTATION)
    out = []
    for sel in (after & translate & (np.hypot(qdd[:, 0], qdd[:, 1]) >= accel),
                after & rotate & (np.abs(qdd[:, 2]) >= yaw_accel)):
        idx = np.flatnonzero(sel)
        out.append(float(traj.t[idx[0]]) if idx.size else math.inf)
    return out[0], out[1]


def available_estimate(res: TrackResult) -> np.ndarray:
    """(N, 2) the estimate a controller has at each sample: rows are complete ``latency`` s late."""
    late = int(round(res.latency / res._dt()))
    est = np.empty_like(res.estimate)
    est[late:] = res.estimate[:res.estimate.shape[0] - late]
    est[:late] = res.estimate[0]
    return est


def torque_rms(case: Case, res: TrackResult) -> tuple[float, float, float]:
    """RMS (N m) after the step of the feed-forward torques of eq. (21) with the tracked (available)
    and with the stale parameters less those with the true ones, and of the true ones. The torques
    are linear in the parameters: u(p) = u(p0) + du/dm (m - m0) + du/dC (C - C0) (checked)."""
    traj = case.trajectory
    motion = traj.joint_motion()
    u0 = traj.feedforward(P, motion)
    du_m = (traj.feedforward(replace(P, m_ch=P.m_ch + 100.0), motion) - u0) / 100.0
    du_c = (traj.feedforward(replace(P, C_ch=P.C_ch + 10.0), motion) - u0) / 10.0
    n = min(traj.t.size, res.t.size)
    after = traj.t[:n] >= case.t_applied
    u0, du_m, du_c = u0[:n], du_m[:n], du_c[:n]
    truth = u0 + du_m * (case.truth[0] - P.m_ch) + du_c * (case.truth[1] - P.C_ch)
    check = traj.feedforward(replace(P, m_ch=float(case.truth[0]), C_ch=float(case.truth[1])), motion)[:n]
    assert np.allclose(truth, check, atol=1e-6 * np.abs(check).max()), "feed-forward not linear in m_ch, C_ch"
    est = available_estimate(res)[:n]
    tracked = u0 + du_m * (est[:, :1] - P.m_ch) + du_c * (est[:, 1:] - P.C_ch)
    rms = [float(np.sqrt(np.mean(x[after] ** 2))) for x in (tracked - truth, u0 - truth, truth)]
    return rms[0], rms[1], rms[2]


def _error_pct(res: TrackResult, truth: np.ndarray, t: float, i: int) -> float | None:
    return 100 * (res.value_at(t)[0][i] / truth[i] - 1) if math.isfinite(t) else None


def evaluate(case: Case, res: TrackResult, accel: float, yaw_accel: float) -> dict:
    """The run's figures (module docstring)."""
    t_m, t_c = first_excited(case.trajectory, case.t_applied, accel, yaw_accel)
    out = {"seed": case.seed, "t_step": case.t_applied, "mass_pct": 100 * case.step.mass / P.m_ch,
           "C_pct": 100 * (case.truth[1] / P.C_ch - 1), "excited_m": t_m, "excited_C": t_c,
           "false_before": sum(e.t_detected < case.t_applied for e in res.events),
           "hours_before": case.t_applied / 3600.0, "events": [e.to_dict() for e in res.events], "detection": None}
    after = [e for e in res.events if e.t_detected >= case.t_applied]
    if after:
        e = after[0]
        out["detection"] = {
            "parameter": e.parameter, "t": e.t_detected, "latency": e.t_detected - min(t_m, t_c),
            "change_estimate": e.t_change_estimate,
            "m_ch_error_pct_3s": _error_pct(res, case.truth, e.t_detected + 3, 0),
            "C_ch_error_pct_3s": _error_pct(res, case.truth, e.t_detected + 3, 1),
            "m_ch_error_pct_3s_excited": _error_pct(res, case.truth, max(e.t_detected, t_m) + 3, 0),
            "C_ch_error_pct_3s_excited": _error_pct(res, case.truth, max(e.t_detected, t_c) + 3, 1)}
    for i, name in enumerate(("m_ch", "C_ch")):
        out[f"{name}_final_error_pct"] = 100 * (res.estimate[-1, i] / case.truth[i] - 1)
    out["torque_rms_tracked"], out["torque_rms_stale"], out["torque_rms_true"] = torque_rms(case, res)
    return out


def step_study(seeds: list[int], settings: TrackerSettings, accel: float, yaw_accel: float,
               engine: str = "ours") -> list[dict]:
    rows = []
    for seed in seeds:
        case = step_case(seed, engine)
        rows.append(evaluate(case, track([case.log], PROTOTYPE, P, settings=settings), accel, yaw_accel))
    return rows


def false_alarm_study(hours: float, settings: TrackerSettings, first_seed: int = 101, engine: str = "ours",
                      observe=None) -> dict:
    """Alarms on step-free driving: ``hours`` in runs of 600 s (seeds ``first_seed``, ...); ``observe``
    (optional) is called with each run's :class:`TrackResult`."""
    runs = max(1, math.ceil(hours * 3600 / FREE_DURATION))
    alarms, total, where = 0, 0.0, []
    for seed in range(first_seed, first_seed + runs):
        log, _ = simulated_log(experiment("driving", duration=FREE_DURATION, seed=seed), (), seed, engine)
        res = track([log], PROTOTYPE, P, settings=settings)
        if observe is not None:
            observe(res)
        alarms += len(res.events)
        where += [(seed, e.parameter, round(e.t_detected, 2)) for e in res.events]
        total += float(log.t[-1] - log.t[0])
    return {"runs": runs, "hours": total / 3600, "alarms": alarms, "where": where}


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


def _errors(hit: list[dict], key: str, goal: float) -> str:
    err = [abs(h[key]) for h in hit if h[key] is not None]
    return (f"max {max(err, default=math.nan):.2f} %, median {_pct(err, 50):.2f} %, "
            f"within {goal:g} %: {sum(e <= goal for e in err)} of {len(err)}")


def acceptance_table(rows: list[dict], free: dict | None) -> list[tuple[str, str]]:
    """(quantity, measured) lines of the acceptance table."""
    hit = [r["detection"] for r in rows if r["detection"] is not None]
    missed = [f"seed {r['seed']} ({r['mass_pct']:+.0f} %)" for r in rows if r["detection"] is None]
    by = {p: sum(h["parameter"] == p for h in hit) for p in ("m_ch", "C_ch")}
    lat = [h["latency"] for h in hit]
    out = [("payload change detected", f"{len(hit)} of {len(rows)} (first alarm m_ch {by['m_ch']}, C_ch {by['C_ch']})"
            + (f"; missed: {', '.join(missed)}" if missed else "")),
           ("latency after the first excited motion", f"median {_pct(lat, 50):.2f} s, p95 {_pct(lat, 95):.2f} s, "
            f"max {max(lat, default=math.nan):.2f} s, within {GOALS['latency']:g} s: "
            f"{sum(x <= GOALS['latency'] for x in lat)} of {len(lat)}")]
    for name in ("m_ch", "C_ch"):
        what = "translation" if name == "m_ch" else "rotation"
        out.append((f"{name} error 3 s after detection", _errors(hit, f"{name}_error_pct_3s", GOALS[name])))
        out.append((f"{name} error 3 s after detection and the first {what}",
                    _errors(hit, f"{name}_error_pct_3s_excited", GOALS[name])))
        final = [abs(r[f"{name}_final_error_pct"]) for r in rows]
        out.append((f"{name} error at the end of the run", f"max {max(final):.2f} %"))
    tr, st, true = (np.array([r[f"torque_rms_{k}"] for r in rows]) for k in ("tracked", "stale", "true"))
    out.append(("feed-forward motor-torque RMS error after the step, tracked vs stale",
                f"median {np.median(tr) * 1e3:.1f} vs {np.median(st) * 1e3:.1f} mN m "
                f"({np.median(tr / true) * 100:.1f} % vs {np.median(st / true) * 100:.1f} % of the torques' RMS); "
                f"tracked/stale median "
                f"{np.median(tr / st):.2f}, max {np.max(tr / st):.2f}"))
    before, hours_before = sum(r["false_before"] for r in rows), sum(r["hours_before"] for r in rows)
    out.append(("false alarms before the step", f"{before} in {hours_before:.2f} h"))
    if free is not None:
        out.append(("false alarms on step-free driving", f"{free['alarms']} in {free['hours']:.2f} h "
                    f"({free['alarms'] / free['hours']:.2f} per h; {free['runs']} runs of {FREE_DURATION:.0f} s)"))
    return out


def run_line(r: dict) -> str:
    """One line per run: the step, the detection, errors 3 s after, torque RMS tracked / stale."""
    d = r["detection"]
    fmt = lambda x: "  n/a " if x is None else f"{x:+6.2f}"  # noqa: E731
    seen = (f"{d['parameter']:4s} lat {d['latency']:5.2f} s, 3 s after: m {fmt(d['m_ch_error_pct_3s'])} % "
            f"C {fmt(d['C_ch_error_pct_3s'])} %, after excitation m {fmt(d['m_ch_error_pct_3s_excited'])} % "
            f"C {fmt(d['C_ch_error_pct_3s_excited'])} %") if d else "missed"
    return (f"seed {r['seed']:2d} step {r['t_step']:6.2f} s {r['mass_pct']:+5.1f} % (C {r['C_pct']:+5.1f} %): {seen}; "
            f"end m {r['m_ch_final_error_pct']:+.2f} % C {r['C_ch_final_error_pct']:+.2f} %; "
            f"torque {r['torque_rms_tracked'] * 1e3:.1f}/{r['torque_rms_stale'] * 1e3:.1f} mN m")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1, help="step runs use seeds first-seed, first-seed + 1, ...")
    ap.add_argument("--free-hours", type=float, default=2.0, help="step-free driving (0: skip)")
    ap.add_argument("--free-first-seed", type=int, default=101, help="step-free runs use seeds from this one (201: the "
                    "second set)")
    ap.add_argument("--accel", type=float, default=0.1, help="m/s^2: an excited translation")
    ap.add_argument("--yaw-accel", type=float, default=0.3, help="rad/s^2: an excited rotation")
    ap.add_argument("--engine", choices=("ours", "mujoco"), default="ours", help="the plant of the runs")
    ap.add_argument("--json", default=None, help="write every run's figures to this file")
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    settings = TrackerSettings()
    t0 = time.perf_counter()
    rows = step_study(list(range(args.first_seed, args.first_seed + args.seeds)), settings, args.accel, args.yaw_accel,
                      args.engine)
    t1 = time.perf_counter()
    free = (false_alarm_study(args.free_hours, settings, args.free_first_seed, engine=args.engine)
            if args.free_hours > 0 else None)
    t2 = time.perf_counter()
    for r in rows:
        print(run_line(r))
    print_results(acceptance_table(rows, free), rows, free, args.markdown, args.json)
    print(f"(step study {t1 - t0:.0f} s, false-alarm study {t2 - t1:.0f} s)")


def print_results(lines: list[tuple[str, str]], rows: list[dict], free: dict | None, markdown: bool,
                  json_path: str | None) -> None:
    """Where the false alarms were, the acceptance table (Markdown rows, or aligned text) and, when
    ``json_path`` is given, every run's figures as JSON."""
    if free is not None and free["where"]:
        print("false alarms:", free["where"])
    if markdown:
        print("\n| | |\n|---|---|\n" + "\n".join(f"| {k} | {v} |" for k, v in lines))
    else:
        width = max((len(k) for k, _ in lines), default=0) + 2
        print("\n".join(f"{k:{width}s} {v}" for k, v in lines))
    if json_path:
        with open(json_path, "w", encoding="utf-8") as fh:
            json.dump({"runs": rows, "free": free}, fh, indent=1, default=str)


if __name__ == "__main__":
    main()
