"""Peak memory of ``identify`` on one long continuous log (issue 12: a 10-hour log, 18 M samples at
500 Hz, under 1 GB and independent of the length): the simulated identification sequence is
repeated in time into one Parquet file (written a copy at a time), then identified in a fresh
process that reads it in pieces (:func:`agvdyn.io.chunks.log_pieces`).

    .venv/bin/python benchmarks/bench_long_log.py [--hours 0.5 2 10]

Prints per length: samples, seconds of work, samples/s, peak RSS, and the largest relative
difference of the parameters from the shortest log's (the same motion repeated).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


def worker(path: str) -> dict:
    from agvdyn.identification import identify
    from agvdyn.io import open_logs

    t0 = time.perf_counter()
    ident = identify(open_logs(path), keep_blocks=False)
    return {"samples": ident.n_samples, "seconds": time.perf_counter() - t0,
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "values": ident.parameters.to_vector().tolist()}


def write_long_log(source: Path, out: Path, hours: float) -> int:
    """``source`` repeated in time (wheel angles continued) up to ``hours``; returns the rows written."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from agvdyn.io import read_log, sidecar_path

    log = read_log(source)
    frame = log.frame.reset_index(drop=True)
    dt = float(np.median(np.diff(frame["t"])))
    span = float(frame["t"].iloc[-1] - frame["t"].iloc[0]) + dt
    copies = max(1, int(round(hours * 3600 / span)))
    beta = [c for c in frame.columns if c.startswith("beta")]
    step = frame[beta].iloc[-1].to_numpy() - frame[beta].iloc[0].to_numpy()
    writer = None
    for k in range(copies):
        part = frame.copy()
        part["t"] = part["t"] + k * span
        part[beta] = part[beta].to_numpy() + k * step
        table = pa.Table.from_pandas(part, preserve_index=False)
        if writer is None:
            writer = pq.ParquetWriter(out, table.schema)
        writer.write_table(table)
    writer.close()
    sidecar_path(out).write_text(sidecar_path(source).read_text())
    return copies * len(frame)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, nargs="+", default=[0.5, 2.0, 10.0])
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker)))
        return
    from agvdyn.simulation import simulate

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        source = simulate("identification", seed=1).write(tmp / "one.parquet")
        first = None
        for hours in args.hours:
            path = tmp / f"long_{hours:g}h.parquet"
            rows = write_long_log(source, path, hours)
            out = subprocess.run([sys.executable, __file__, "--worker", str(path)], capture_output=True, text=True)
            if out.returncode:
                raise SystemExit(f"worker failed on {hours} h:\n{out.stderr}")
            res = json.loads(out.stdout.strip().splitlines()[-1])
            first = first or res["values"]
            diff = max(abs(a / b - 1) for a, b in zip(res["values"], first))
            print(f"{hours:5g} h, {rows:,} samples: {res['seconds']:.1f} s of work = "
                  f"{res['samples'] / res['seconds'] / 1e6:.2f} M samples/s, peak RSS {res['peak_mb']:.0f} MB, "
                  f"parameters within {diff:.1e} of the shortest log's")
            path.unlink()


if __name__ == "__main__":
    main()
