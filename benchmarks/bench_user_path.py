"""Every command as a user meets it (issue 28): wall time of ``agvdyn <command>`` in fresh processes,
start-up included, on input files written the way other tools write them, next to the same work
timed inside one warm process.

    .venv/bin/python benchmarks/bench_user_path.py [--repeat 5] [--data DIR] [--only NAME ...] [--markdown]
                                                   [--json FILE] [--from-json FILE] [--before FILE]

Inputs (written once into ``--data``, default a temporary folder; an existing folder is reused):

* ``log71.parquet``: the 71 s acceptance log of ``bench_throughput.py`` (35,500 samples at 500 Hz,
  simulated, seed 1) in our own format, with its sidecar; ``own/`` 25 copies of it.
* ``ext/``: 25 copies of the same samples as another tool writes them: ``DataFrame.to_parquet`` of
  pandas (pyarrow, snappy, dictionary pages), a plain string ``segment`` column (None where no
  segment), float32 torques, no sidecar.
* ``logger.csv`` + ``logger.yaml``: a data logger's CSV (time in ms, steering in degrees, motor
  encoder counts as integers, motor currents, a numeric phase column; the columns of
  ``examples/mappings/csv_datalogger.yaml``) and its mapping (that example with ``i_G``).
* ``bag/`` + ``bag.yaml``: an MCAP bag of ``sensor_msgs/msg/JointState`` (all eight joints per
  message, ros2_control naming) at 500 Hz with jittered header stamps (+-0.4 ms, uniform; the values
  are those at the jittered stamps), and its mapping (``examples/mappings/ros2_control.yaml`` with
  ``i_G`` and the segments as time ranges).
* ``rec160.parquet``: a 160 s recording (the identification sequence with five steering periods,
  seed 2, cut to 160.0 s) and ``lane.parquet``, a lane change (seed 3) as validation log.

Each case runs once unmeasured (file cache, numba's and the filter designs' caches), then
``--repeat`` times in fresh processes (``.venv/bin/agvdyn``, output to /dev/null): median and range.
The in-process figure runs the same command line through ``agvdyn.cli.app`` inside one process,
after one warm-up run: what is left is the work itself. ``--markdown`` prints the README's section
"Performance as a user meets it".
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EXE = Path(sys.executable).with_name("agvdyn")
SAMPLES71 = 35_500
COPIES = 25
REC_SECONDS = 160.0


@dataclass(frozen=True)
class Case:
    name: str
    what: str
    args: tuple[str, ...]
    samples: int = 0  # samples read, for the per-sample rate
    target: float | None = None  # s, fresh process


def cases(data: Path) -> list[Case]:
    own = [str(p) for p in sorted((data / "own").glob("*.parquet"))]
    ext = [str(p) for p in sorted((data / "ext").glob("*.parquet"))]
    out = str(data / "out")
    n25 = COPIES * SAMPLES71
    return [
        Case("identify-own-25", f"`identify`, 25 logs in our own Parquet ({n25:,} samples)",
             ("identify", *own, "--out", f"{out}/p.yaml"), n25),
        Case("identify-ext-25", f"`identify`, 25 pandas-written Parquet logs ({n25:,} samples)",
             ("identify", *ext, "--out", f"{out}/p.yaml"), n25, 1.2),
        Case("identify-own-1", f"`identify`, one log in our own Parquet ({SAMPLES71:,} samples)",
             ("identify", own[0], "--out", f"{out}/p.yaml"), SAMPLES71),
        Case("identify-ext-1", "`identify`, one pandas-written Parquet log",
             ("identify", ext[0], "--out", f"{out}/p.yaml"), SAMPLES71, 0.6),
        Case("identify-csv-1", "`identify`, one data-logger CSV with a mapping",
             ("identify", str(data / "logger.csv"), "--mapping", str(data / "logger.yaml"), "--out", f"{out}/p.yaml"),
             SAMPLES71),
        Case("identify-bag-1", "`identify`, one MCAP bag (jittered stamps) with a mapping",
             ("identify", str(data / "bag"), "--mapping", str(data / "bag.yaml"), "--out", f"{out}/p.yaml"),
             SAMPLES71),
        Case("simulate", "`simulate identification` (117.6 s of vehicle time)",
             ("simulate", "identification", "--out", f"{out}/sim.parquet", "--quiet"), 0, 0.6),
        Case("report", "`report`, 160 s recording + lane change",
             ("report", "--ident", str(data / "rec160.parquet"), "--validation", str(data / "lane.parquet"),
              "--out", f"{out}/report.html"), 0, 3.0),
        Case("inspect", "`inspect` on the 160 s recording", ("inspect", str(data / "rec160.parquet")), 0, 0.8),
        Case("help", "`agvdyn --help`", ("--help",), 0, 0.3),
        Case("identify-help", "`agvdyn identify --help`", ("identify", "--help"), 0, 0.3),
        Case("report-help", "`agvdyn report --help`", ("report", "--help"), 0, 0.3),
        Case("simulate-help", "`agvdyn simulate --help`", ("simulate", "--help"), 0, 0.3),
    ]


# ---------------------------------------------------------------- inputs, written as other tools do


def write_inputs(data: Path) -> None:
    """The input files of the module docstring, into ``data`` (skipped when already there)."""
    if (data / "done").exists():
        return
    import numpy as np
    import pandas as pd

    sys.path.insert(0, str(HERE))
    from bench_throughput import acceptance_log  # noqa: PLC0415

    from agvdyn.io import read_log, write_log
    from agvdyn.platform import PROTOTYPE
    from agvdyn.simulation import simulate
    from agvdyn.trajectories import identification_sequence

    data.mkdir(parents=True, exist_ok=True)
    for sub in ("own", "ext", "out"):
        (data / sub).mkdir(exist_ok=True)
    source = acceptance_log(data)
    (data / "whole71.parquet").unlink(missing_ok=True)
    (data / "whole71.parquet.yaml").unlink(missing_ok=True)
    log = read_log(source)
    frame = log.frame
    for k in range(COPIES):
        shutil.copy(source, data / "own" / f"log{k:02d}.parquet")
        shutil.copy(f"{source}.yaml", data / "own" / f"log{k:02d}.parquet.yaml")

    # Parquet as pandas writes it: object strings, float32 torques, default compression and encodings.
    ext = frame.copy()
    ext["segment"] = ext["segment"].astype(object).where(ext["segment"].notna(), None)
    for col in ("m_fl", "m_rl", "m_fr", "m_rr"):
        ext[col] = ext[col].astype(np.float32)
    ext.to_parquet(data / "ext" / "log00.parquet")
    for k in range(1, COPIES):
        shutil.copy(data / "ext" / "log00.parquet", data / "ext" / f"log{k:02d}.parquet")

    _write_logger_csv(frame, data, PROTOTYPE.i_G)
    _write_bag(frame, data, PROTOTYPE.i_G, log.segment_runs())

    rec = simulate(identification_sequence(steering_periods=5), seed=2).write(data / "rec_whole.parquet")
    whole = read_log(rec)
    n = int(round(REC_SECONDS / whole.sample_time))
    write_log(data / "rec160.parquet", whole.frame.iloc[:n].reset_index(drop=True), whole.sidecar)
    for p in (rec, Path(f"{rec}.yaml")):
        p.unlink(missing_ok=True)
    simulate("lane-change", seed=3).write(data / "lane.parquet")
    pd.DataFrame  # noqa: B018 - pandas is the writer of the external files above
    (data / "done").write_text("ok\n")


PHASES = {"align": 0, "steer_left": 1, "steer_right": 2, "straight": 3, "rotation": 4}


def _write_logger_csv(frame, data: Path, i_G: float) -> None:
    """The data logger's CSV: the inverse of examples/mappings/csv_datalogger.yaml."""
    import numpy as np
    import pandas as pd

    counts = 4096 / (2 * math.pi) * i_G  # motor-side encoder counts per wheel radian
    out = pd.DataFrame({"time_ms": np.round(frame["t"].to_numpy() * 1000).astype(np.int64)})
    out["steer_L_deg"] = np.degrees(frame["alpha_l"].to_numpy()).round(4)
    out["steer_R_deg"] = np.degrees(frame["alpha_r"].to_numpy()).round(4)
    for w, sign in (("fl", 1), ("rl", 1), ("fr", -1), ("rr", -1)):
        out[f"enc_{w.upper()}"] = np.round(sign * frame[f"beta_{w}"].to_numpy() * counts).astype(np.int64)
    for w, sign in (("fl", 1), ("rl", 1), ("fr", -1), ("rr", -1)):
        out[f"cur_{w.upper()}"] = (sign * frame[f"m_{w}"].to_numpy() / 0.12).round(4)
    seg = frame["segment"].astype(object)
    out["phase"] = [PHASES.get(s, 0) if isinstance(s, str) else 0 for s in seg]
    out.to_csv(data / "logger.csv", index=False)
    mapping = (ROOT / "examples" / "mappings" / "csv_datalogger.yaml").read_text()
    (data / "logger.yaml").write_text(mapping.replace("# i_G: 25 ", f"i_G: {i_G!r} #"))


def _write_bag(frame, data: Path, i_G: float, runs) -> None:
    """An MCAP bag of JointState messages at 500 Hz with jittered header stamps."""
    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    js, header, stamp = (ts.types[n] for n in ("sensor_msgs/msg/JointState", "std_msgs/msg/Header",
                                               "builtin_interfaces/msg/Time"))
    names = ["front_left_steering_joint", "rear_left_steering_joint", "front_right_steering_joint",
             "rear_right_steering_joint", "front_left_wheel_joint", "rear_left_wheel_joint",
             "front_right_wheel_joint", "rear_right_wheel_joint"]
    t = frame["t"].to_numpy()
    rng = np.random.default_rng(7)
    start = 1_731_000_000_000_000_000
    stamps = start + np.round(t * 1e9).astype(np.int64) + rng.integers(-400_000, 400_001, t.size)
    s = (stamps - start) / 1e9
    s = np.clip(s, t[0], t[-1])

    def at(col):
        return np.interp(s, t, frame[col].to_numpy())

    a_l, a_r = at("alpha_l"), at("alpha_r")
    position = np.column_stack([a_l, -a_l, a_r, -a_r] + [at(f"beta_{w}") for w in ("fl", "rl", "fr", "rr")])
    nan4 = np.full((t.size, 4), np.nan)
    effort = np.column_stack([nan4] + [at(f"m_{w}") * i_G for w in ("fl", "rl", "fr", "rr")])
    path = data / "bag"
    shutil.rmtree(path, ignore_errors=True)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for k, ns in enumerate(stamps.tolist()):
            msg = js(header=header(stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="base_link"),
                     name=names, position=position[k], velocity=np.array([], dtype=float), effort=effort[k])
            writer.write(conn, ns + 150_000, ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
    mapping = (ROOT / "examples" / "mappings" / "ros2_control.yaml").read_text()
    mapping = mapping.replace("# i_G: 25 ", f"i_G: {i_G!r} #").split("# Optional: which time ranges")[0]
    mapping += "segments:\n" + "".join(f"  - {{name: {r.name}, start: {r.t_start!r}, end: {r.t_end!r}}}\n"
                                       for r in runs)
    (data / "bag.yaml").write_text(mapping)


# ---------------------------------------------------------------- timing


def fresh(args: tuple[str, ...], repeat: int, cpu: list[float] | None = None) -> list[float]:
    """Wall times of ``repeat`` fresh processes; their CPU times (user + system) appended to ``cpu``."""
    times = []
    for _ in range(repeat):
        c0, t0 = os.times(), time.perf_counter()
        done = subprocess.run([str(EXE), *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        times.append(time.perf_counter() - t0)
        c1 = os.times()
        if cpu is not None:
            cpu.append(c1.children_user - c0.children_user + c1.children_system - c0.children_system)
        if done.returncode:
            raise SystemExit(f"agvdyn {' '.join(args)} failed ({done.returncode}):\n{done.stderr}")
    return times


def in_process(args: tuple[str, ...], repeat: int) -> float:
    """Median seconds of the command run ``repeat`` times inside one process after a warm-up run."""
    with tempfile.NamedTemporaryFile("r", suffix=".json", delete=False) as f:
        result = f.name
    try:
        subprocess.run([sys.executable, __file__, "--worker", result, "--repeat", str(repeat), "--", *args],
                       check=True, stdout=subprocess.DEVNULL)
        return json.loads(Path(result).read_text())["median"]
    finally:
        os.unlink(result)


def worker(result: str, args: list[str], repeat: int) -> None:
    import contextlib

    from agvdyn._memory import keep_freed_memory

    from agvdyn.cli import app, one_blas_thread

    one_blas_thread()  # as agvdyn.cli.main
    keep_freed_memory(trim=256 << 20, top_pad=64 << 20)

    def run() -> float:
        t0 = time.perf_counter()
        with open(os.devnull, "w") as null, contextlib.redirect_stdout(null):
            try:
                app(list(args), prog_name="agvdyn", standalone_mode=False)
            except SystemExit:
                pass
        return time.perf_counter() - t0

    run()
    times = [run() for _ in range(repeat)]
    Path(result).write_text(json.dumps({"median": statistics.median(times), "times": times}))


def measure(selected: list[Case], repeat: int) -> list[dict]:
    rows = []
    for case in selected:
        fresh(case.args, 1)  # caches warm: the file cache, numba's kernels, filter designs
        cpu: list[float] = []
        times = fresh(case.args, repeat, cpu)
        warm = in_process(case.args, max(3, repeat // 2))
        rows.append({"name": case.name, "what": case.what, "samples": case.samples, "target": case.target,
                     "median": statistics.median(times), "min": min(times), "max": max(times), "warm": warm,
                     "cpu": statistics.median(cpu)})
        print(_line(rows[-1]), flush=True)
    return rows


def _line(row: dict) -> str:
    rate = f" {row['samples'] / row['median'] / 1e6:5.2f} M samples/s" if row["samples"] else " " * 19
    target = f"  (target <= {row['target']:g} s)" if row["target"] else ""
    return (f"{row['name']:<16} fresh {row['median']:6.3f} s [{row['min']:.3f}-{row['max']:.3f}] cpu {row['cpu']:6.3f} s"
            f"{rate}   in-process {row['warm']:6.3f} s{target}")


def per_sample_note(rows: list[dict]) -> list[str]:
    by = {r["name"]: r for r in rows}
    own = by.get("identify-own-1")
    if own is None:
        return []
    out = []
    for name in ("identify-ext-1", "identify-csv-1", "identify-bag-1"):
        if name in by:
            out.append(f"{name}: {by[name]['median'] / own['median'] - 1:+.0%} per sample against our own format "
                       "(one log, fresh process; target within +15 %)")
    return out


def markdown(rows: list[dict], repeat: int, load: tuple[float, float], before: dict | None = None) -> str:
    """The README's section: the table of ``rows`` (and the fresh-process medians of ``before``, rows
    of an earlier run by case name, when given)."""
    before_rows = {r["name"]: r for r in (before or {}).get("rows", [])}
    head = "| command | fresh process | range | CPU (user + system) | rate | in-process |"
    rule = "|---|---|---|---|---|---|"
    if before_rows:
        head, rule = head + " before (fresh) |", rule + "---|"
    lines = [
        "## Performance as a user meets it",
        "",
        f"`benchmarks/bench_user_path.py` (this section is its `--markdown` output): each command in fresh "
        f"processes, start-up included, median of {repeat} and range, on {os.cpu_count()} cores (load average "
        f"{load[0]:.1f} at the start, {load[1]:.1f} at the end; the machine is shared), on inputs written the way "
        "other tools write them (see the script); next to it the same command run inside one warm process"
        + (" and the fresh-process median before issue 28's changes (an earlier run, "
           f"load average {before['load'][0]:.1f} at its start)" if before_rows else "") + ".",
        "",
        head + " target |",
        rule + "---|",
    ]
    for r in rows:
        rate = f"{r['samples'] / r['median'] / 1e6:.2f} M samples/s" if r["samples"] else ""
        target = (f"<= {r['target']:g} s ({'met' if r['median'] <= r['target'] else 'not met'})"
                  if r["target"] else "")
        cpu = f"{r['cpu']:.2f} s" if "cpu" in r else ""
        was = f" {before_rows[r['name']]['median']:.2f} s |" if r["name"] in before_rows else (" |" if before_rows else "")
        lines.append(f"| {r['what']} | {r['median']:.2f} s | {r['min']:.2f}-{r['max']:.2f} s | {cpu} | {rate} | "
                     f"{r['warm']:.2f} s |{was} {target} |")
    notes = per_sample_note(rows)
    if notes:
        lines += ["", "Per-sample cost against our own format (one log, fresh process; target within +15 %): "
                  + ", ".join(f"{n.split(':')[0].removeprefix('identify-').removesuffix('-1')} "
                              f"{n.split(': ')[1].split(' ')[0]}" for n in notes) + "."]
    lines += ["", "Where a fresh one-log `identify` spends its ~0.45 s: the work itself ~0.07 s; imports ~0.3 s (the "
              "command line: typer, pydantic, rich ~0.12 s; numpy ~0.05 s; pyarrow ~0.05 s; agvdyn's io and "
              "identification ~0.1 s); no numba (its kernels are compiled ahead of time by `make`), no scipy, no "
              "pandas; see docs/identification.md, \"Start-up: the user's path\"."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--data", type=Path, help="folder of the inputs (written when missing, reused otherwise)")
    parser.add_argument("--only", nargs="+", help="case names to run")
    parser.add_argument("--markdown", action="store_true", help="print the README section")
    parser.add_argument("--json", type=Path, help="also write the rows as JSON here")
    parser.add_argument("--from-json", type=Path, help="print the README section of rows written by --json (no runs)")
    parser.add_argument("--before", type=Path, help="rows of an earlier run (--json) shown next to these")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("rest", nargs="*", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, args.rest, args.repeat)
        return
    before = json.loads(args.before.read_text()) if args.before else None
    if args.from_json:
        saved = json.loads(args.from_json.read_text())
        print(markdown(saved["rows"], saved.get("repeat", args.repeat), tuple(saved["load"]), before))
        return
    tmp = None
    data = args.data
    if data is None:
        tmp = tempfile.TemporaryDirectory()
        data = Path(tmp.name)
    try:
        write_inputs(data)
        selected = [c for c in cases(data) if not args.only or c.name in args.only]
        load0 = os.getloadavg()[0]
        print(f"{os.cpu_count()} cores; load average {load0:.1f} at the start", flush=True)
        rows = measure(selected, args.repeat)
        load1 = os.getloadavg()[0]
        print(f"load average {load1:.1f} at the end")
        for note in per_sample_note(rows):
            print(note)
        if args.json:
            args.json.write_text(json.dumps({"rows": rows, "load": [load0, load1], "repeat": args.repeat}, indent=1))
        if args.markdown:
            print()
            print(markdown(rows, args.repeat, (load0, load1), before))
    finally:
        if tmp is not None:
            tmp.cleanup()


if __name__ == "__main__":
    main()
