"""Throughput and memory of ``identify`` on many logs (issue 12): samples per second of work and
peak RSS for 1, 25 and 100 copies of one simulated log, each in a fresh process, next to the
vectorised row-stacked reference and a naive per-sample loop measured in the same run, and the
``agvdyn identify`` command as a user meets it (start-up included).

    .venv/bin/python benchmarks/bench_throughput.py [--copies 1 25 100] [--experiment 71s|identification]
                                                    [--repeat 3] [--threads 2] [--log FILE]

* The log (acceptance case, default ``71s``): the identification sequence with one steering period
  and 23 s straight and rotation segments, simulated (seed 1) and cut to its first 71.0 s
  (35,500 samples at 500 Hz); 25 copies are 887,500 samples. ``identification``: the whole
  117.6 s default sequence (58,804 samples).
* ``normal equations``: :func:`agvdyn.identification.identify` with ``keep_blocks=False``, logs read
  and reduced to Gram blocks (what ``agvdyn identify`` and ``agvdyn batch`` run), with
  ``workers=1`` (one core) and ``workers=2`` (two threads); the rate is samples / wall time of
  work (start-up and a warm-up identification excluded), and samples / CPU time of the process
  (the machine may be shared); ``--repeat`` fresh processes per case, alternated between the
  thread counts, give the median and the range.
* ``stacked reference``: every log's equation blocks kept and all rows stacked in memory
  (``fit_blocks(..., stacked=True)``), the previous design; the largest relative difference of
  the ten parameters and four offsets against it is printed.
* ``naive``: rows of eq. (19) built one sample at a time in Python (``bench_identification.naive_rows``)
  on a subset, extrapolated linearly.

Targets: >= 2 M samples/s of work for 25 copies, peak RSS <= 600 MB, 100 copies no more than
100 MB above 25. BLAS and numba threads are pinned to 1.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(paths: list[str], mode: str, workers: int) -> dict:
    """Runs in a fresh process: one warm-up identification (imports, numba cache), then the timed one."""
    from agvdyn.identification import IdentificationSettings, fit_blocks, identify, load_logs, platform_for
    from agvdyn.identification.rows import log_rows

    import agvdyn.identification.pipeline as pipeline

    from agvdyn.io import open_logs

    identify(open_logs(paths[:2]), keep_blocks=False, workers=workers)
    regression = [0.0]
    fit = pipeline.fit_regression

    def timed_fit(*args, **kwargs):  # the regression stage's share (estimator, uncertainty, checks)
        start = time.perf_counter()
        try:
            return fit(*args, **kwargs)
        finally:
            regression[0] += time.perf_counter() - start

    pipeline.fit_regression = timed_fit
    t0, c0 = time.perf_counter(), time.process_time()
    if mode == "normal":
        ident = identify(open_logs(paths), keep_blocks=False, workers=workers)
    else:  # the row-stacked reference: all blocks in memory, one stacked regression
        settings = IdentificationSettings()
        logs = load_logs(paths)
        geometry = platform_for(logs, None)
        blocks = [b for log in logs for b in log_rows(log, geometry, settings).blocks]
        ident = fit_blocks(blocks, geometry, settings=settings, stacked=True,
                           n_samples=sum(len(log.t) for log in logs))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    values = list(ident.parameters.to_vector()) + list(ident.offsets.values())
    return {"samples": ident.n_samples, "seconds": seconds, "cpu": cpu, "peak_mb": _peak_mb(), "values": values,
            "regression": regression[0]}


def _run_worker(paths: list[Path], mode: str, workers: int = 1) -> dict:
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump([str(p) for p in paths], f)
    try:
        out = subprocess.run([sys.executable, __file__, "--worker", f.name, "--mode", mode, "--workers", str(workers)],
                             capture_output=True, text=True)
    finally:
        os.unlink(f.name)
    if out.returncode:
        raise SystemExit(f"worker ({mode}, {len(paths)} logs) failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _median_run(runs: list[dict]) -> dict:
    """The run of median wall time, with the largest peak RSS of all."""
    ordered = sorted(runs, key=lambda r: r["seconds"])
    return {**ordered[len(ordered) // 2], "peak_mb": max(r["peak_mb"] for r in runs)}


def _max_relative_difference(a: list[float], b: list[float]) -> float:
    return max(abs(x / y - 1) if y else abs(x) for x, y in zip(a, b))


def acceptance_log(folder: Path) -> Path:
    """The 71 s log of the acceptance case (see the module docstring), written to ``folder``."""
    from agvdyn.io import read_log, write_log  # noqa: PLC0415
    from agvdyn.simulation import simulate  # noqa: PLC0415
    from agvdyn.trajectories import FourierSeries, default_excitation, identification_sequence  # noqa: PLC0415

    def shorter(name: str, period: float) -> FourierSeries:  # same velocity shape, shorter period
        series = default_excitation(name)
        return FourierSeries(2 * math.pi / period, series.a, series.b, series.start)

    traj = identification_sequence(steering_periods=1, straight=shorter("straight", 23.0),
                                   rotation=shorter("rotation", 23.0))
    whole = read_log(simulate(traj, seed=1).write(folder / "whole71.parquet"))
    frame = whole.frame.iloc[:ACCEPTANCE_SAMPLES].reset_index(drop=True)
    return write_log(folder / "log71.parquet", frame, whole.sidecar)


#: Samples of the acceptance log: 71 s at 500 Hz.
ACCEPTANCE_SAMPLES = 35_500


def _naive_rate(path: Path, n_per_segment: int = 1000) -> float:
    """Samples per second of rows of eq. (19) built one sample at a time in Python
    (``bench_identification.naive_rows``) from the filtered signals of the log."""
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_identification import naive_inputs, naive_rows  # noqa: PLC0415

    from agvdyn.identification import IdentificationSettings, load_logs  # noqa: PLC0415
    from agvdyn.platform import PROTOTYPE  # noqa: PLC0415

    (log,) = load_logs([path])
    inputs = naive_inputs(log, IdentificationSettings())
    t0 = time.perf_counter()
    naive_rows(PROTOTYPE, inputs, n_per_segment)
    seconds = time.perf_counter() - t0
    return sum(min(n_per_segment, x[1].shape[0]) for x in inputs) / seconds


def _cli_wall(paths: list[Path], out: Path) -> float:
    exe = Path(sys.executable).with_name("agvdyn")
    t0 = time.perf_counter()
    subprocess.run([str(exe), "identify", *map(str, paths), "--out", str(out), "--json"], check=True,
                   capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, nargs="+", default=[1, 25, 100])
    parser.add_argument("--experiment", choices=("71s", "identification"), default="71s",
                        help="the 71 s acceptance log (default) or the whole 117.6 s identification sequence")
    parser.add_argument("--log", type=Path, help="use this log instead of simulating one")
    parser.add_argument("--threads", type=int, default=2, help="workers of the threaded run (default 2)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="fresh processes per case, alternated between the thread counts (default 3): the "
                             "median rate is printed with the range (a shared machine's speed varies by ~30 %%)")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--mode", default="normal", help=argparse.SUPPRESS)
    parser.add_argument("--workers", type=int, default=1, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(json.loads(Path(args.worker).read_text()), args.mode, args.workers)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        source = args.log
        if source is None and args.experiment == "71s":
            source = acceptance_log(tmp)
        elif source is None:
            from agvdyn.simulation import simulate  # noqa: PLC0415

            source = simulate("identification", seed=1).write(tmp / "log.parquet")
        for k in range(max(args.copies)):
            shutil.copy(source, tmp / f"copy{k:03d}.parquet")
            if Path(f"{source}.yaml").exists():
                shutil.copy(f"{source}.yaml", tmp / f"copy{k:03d}.parquet.yaml")
        copies = sorted(tmp.glob("copy*.parquet"))
        print(f"log: {source.name}; {os.cpu_count()} cores; load average {os.getloadavg()[0]:.1f} at the start")
        print(f"naive per-sample loop: {_naive_rate(source) / 1e3:.1f} k samples/s")
        base_rss = None
        for n in args.copies:
            paths = copies[:n]
            counts = sorted({1, args.threads})
            repeats: dict[int, list[dict]] = {w: [] for w in counts}
            for _ in range(max(1, args.repeat)):  # alternated: a slow spell of the host hits both thread counts
                for w in counts:
                    repeats[w].append(_run_worker(paths, "normal", w))
            runs = {w: _median_run(r) for w, r in repeats.items()}
            ref = _run_worker(paths, "stacked") if n <= 25 else None
            for w, fast in runs.items():
                rates = sorted(r["samples"] / r["seconds"] for r in repeats[w])
                rate, cpu_rate = fast["samples"] / fast["seconds"], fast["samples"] / fast["cpu"]
                spread = (f" (range {rates[0] / 1e6:.2f}-{rates[-1] / 1e6:.2f} over {len(rates)} runs)"
                          if len(rates) > 1 else "")
                print(f"{n:4d} logs, {fast['samples']:,} samples, workers={w}: {rate / 1e6:.2f} M samples/s of work"
                      f"{spread} ({fast['seconds']:.2f} s, of which the regression stage {fast['regression']:.2f} s; "
                      f"{cpu_rate / 1e6:.2f} M samples per CPU second), peak RSS {fast['peak_mb']:.0f} MB")
            if ref is not None:
                diff = max(_max_relative_difference(f["values"], ref["values"]) for f in runs.values())
                print(f"      stacked reference {ref['samples'] / ref['seconds'] / 1e6:.2f} M samples/s "
                      f"({ref['samples'] / ref['cpu'] / 1e6:.2f} per CPU second), peak RSS {ref['peak_mb']:.0f} MB; "
                      f"parameters and offsets equal to {diff:.1e} (relative)")
            fast = runs[1]
            if n == 25:
                base_rss = fast["peak_mb"]
            elif n > 25 and base_rss is not None:
                print(f"      peak RSS {fast['peak_mb'] - base_rss:+.0f} MB against 25 logs (goal <= +100 MB)")
            wall = _cli_wall(paths, tmp / "params.yaml")
            print(f"      agvdyn identify (fresh process, start-up included): {wall:.2f} s = "
                  f"{fast['samples'] / wall / 1e6:.2f} M samples/s")


if __name__ == "__main__":
    main()
