"""Throughput and memory of ``identify`` on many logs (issue 12): samples per second of work and
peak RSS for 1, 25 and 100 copies of one simulated identification log (117.6 s, 58,804 samples), each in a fresh process,
next to the vectorised row-stacked reference and a naive per-sample loop measured in the same run,
and the ``agvdyn identify`` command as a user meets it (start-up included).

    .venv/bin/python benchmarks/bench_throughput.py [--copies 1 25 100] [--seconds 71]

* ``normal equations``: :func:`agvdyn.identification.identify` with ``keep_blocks=False``, logs read
  one at a time and reduced to Gram blocks (what ``agvdyn identify`` and ``agvdyn batch`` run).
* ``stacked reference``: every log's equation blocks kept and all rows stacked in memory
  (``fit_blocks(..., stacked=True)``), the previous design.
* ``naive``: rows of eq. (19) built one sample at a time in Python (``bench_identification.naive_rows``)
  on a subset, extrapolated linearly.

Targets: >= 2 M samples/s of work for 25 copies, peak RSS <= 600 MB, 100 copies no more than
100 MB above 25. One core: BLAS and numba threads are pinned to 1.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(paths: list[str], mode: str) -> dict:
    """Runs in a fresh process: one warm-up identification (imports, numba cache), then the timed one."""
    from agvdyn.identification import IdentificationSettings, fit_blocks, identify, load_logs, platform_for
    from agvdyn.identification.rows import log_rows

    identify(paths[:1], keep_blocks=False)
    t0 = time.perf_counter()
    if mode == "normal":
        ident = identify(paths, keep_blocks=False)
    else:  # the row-stacked reference: all blocks in memory, one stacked regression
        settings = IdentificationSettings()
        logs = load_logs(paths)
        geometry = platform_for(logs, None)
        blocks = [b for log in logs for b in log_rows(log, geometry, settings).blocks]
        ident = fit_blocks(blocks, geometry, settings=settings, stacked=True,
                           n_samples=sum(len(log.t) for log in logs))
    seconds = time.perf_counter() - t0
    return {"samples": ident.n_samples, "seconds": seconds, "peak_mb": _peak_mb(),
            "m_ch": ident.parameters.m_ch}


def _run_worker(paths: list[Path], mode: str) -> dict:
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump([str(p) for p in paths], f)
    try:
        out = subprocess.run([sys.executable, __file__, "--worker", f.name, "--mode", mode],
                             capture_output=True, text=True)
    finally:
        os.unlink(f.name)
    if out.returncode:
        raise SystemExit(f"worker ({mode}, {len(paths)} logs) failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


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
    parser.add_argument("--seconds", type=float, default=0.0,
                        help="cut the simulated identification log to its first SECONDS (default 0: the whole "
                             "117.6 s sequence; its rotation phase starts after 71 s)")
    parser.add_argument("--log", type=Path, help="use this log instead of simulating one")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--mode", default="normal", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(json.loads(Path(args.worker).read_text()), args.mode)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        source = args.log
        if source is None:
            from agvdyn.io import read_log, write_log  # noqa: PLC0415
            from agvdyn.simulation import simulate  # noqa: PLC0415

            source = simulate("identification", seed=1).write(tmp / "log.parquet")
            if args.seconds > 0:
                log = read_log(source)
                frame = log.frame[log.frame["t"] <= log.frame["t"].iloc[0] + args.seconds]
                source = write_log(tmp / "cut.parquet", frame, log.sidecar)
        for k in range(max(args.copies)):
            shutil.copy(source, tmp / f"copy{k:03d}.parquet")
            if Path(f"{source}.yaml").exists():
                shutil.copy(f"{source}.yaml", tmp / f"copy{k:03d}.parquet.yaml")
        copies = sorted(tmp.glob("copy*.parquet"))
        print(f"log: {source.name}; one core")
        print(f"naive per-sample loop: {_naive_rate(source) / 1e3:.1f} k samples/s")
        base_rss = None
        for n in args.copies:
            paths = copies[:n]
            fast = _run_worker(paths, "normal")
            ref = _run_worker(paths, "stacked") if n <= 25 else None
            rate = fast["samples"] / fast["seconds"]
            line = (f"{n:4d} logs, {fast['samples']:,} samples: {rate / 1e6:.2f} M samples/s of work, "
                    f"peak RSS {fast['peak_mb']:.0f} MB")
            if ref is not None:
                line += (f" | stacked reference {ref['samples'] / ref['seconds'] / 1e6:.2f} M samples/s, "
                         f"peak RSS {ref['peak_mb']:.0f} MB, m_ch equal to {abs(ref['m_ch'] / fast['m_ch'] - 1):.1e}")
            print(line)
            if n == 25:
                base_rss = fast["peak_mb"]
            elif n > 25 and base_rss is not None:
                print(f"      peak RSS {fast['peak_mb'] - base_rss:+.0f} MB against 25 logs (goal <= +100 MB)")
            wall = _cli_wall(paths, tmp / "params.yaml")
            print(f"      agvdyn identify (fresh process, start-up included): {wall:.2f} s = "
                  f"{fast['samples'] / wall / 1e6:.2f} M samples/s")


if __name__ == "__main__":
    main()
