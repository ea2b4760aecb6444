"""Speed of agvdyn.io: reading a 30-minute 500 Hz log (900,000 rows) in our schema (Parquet, CSV),
and converting a ROS 2 bag of JointState messages (messages per second, sqlite3 and MCAP).

Run: .venv/bin/python benchmarks/bench_io.py [--bag-seconds 60]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from agvdyn.io import Log, load_log, read_log, read_mapping, write_bag, write_log
from agvdyn.platform import PROTOTYPE

MAPPING = Path(__file__).resolve().parents[1] / "examples" / "mappings" / "ros2_control.yaml"


def frame(n: int, dt: float = 0.002) -> pd.DataFrame:
    t = np.arange(n) * dt
    rng = np.random.default_rng(0)
    data = {"t": t, "alpha_l": 0.5 * np.sin(0.3 * t), "alpha_r": 0.4 * np.sin(0.2 * t)}
    for k, w in enumerate(("fl", "rl", "fr", "rr")):
        data[f"beta_{w}"] = 3.0 * t + k
        data[f"m_{w}"] = rng.normal(size=n)
    out = pd.DataFrame(data)
    names = np.array(["steer_left", "steer_right", "straight", "rotation"])
    out["segment"] = names[np.minimum(np.arange(n) * 4 // n, 3)]
    return out


def best_of(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--bag-seconds", type=float, default=60.0, help="length of the bag at 500 Hz")
    args = parser.parse_args()
    n = 900_000
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        f = frame(n)
        pq = write_log(tmp / "big.parquet", f)
        csv = write_log(tmp / "big.csv", f)
        s = best_of(lambda: read_log(pq))
        print(f"read_log parquet: {n} rows in {s:.3f} s ({n / s / 1e6:.2f} M rows/s, checks included)")
        s = best_of(lambda: read_log(csv), 1)
        print(f"read_log csv:     {n} rows in {s:.3f} s ({n / s / 1e6:.2f} M rows/s, checks included)")

        m = int(args.bag_seconds / 0.002)
        log = Log.from_frame(frame(m))
        mapping = read_mapping(MAPPING)
        for storage in ("sqlite3", "mcap"):
            t0 = time.perf_counter()
            bag = write_bag(log, tmp / f"bag_{storage}", mapping, storage, platform=PROTOTYPE)
            w = time.perf_counter() - t0
            t0 = time.perf_counter()
            back = load_log(bag, mapping, PROTOTYPE)  # the mapping's torques are wheel side: i_G needed
            r = time.perf_counter() - t0
            err = np.abs(back.alpha - log.alpha).max()
            print(f"bag {storage:7s}: {m} JointState messages (8 joints): write {m / w:,.0f} msg/s, "
                  f"read+resample+check {m / r:,.0f} msg/s ({r:.2f} s), max |alpha error| {err:.1e} rad")


if __name__ == "__main__":
    main()
