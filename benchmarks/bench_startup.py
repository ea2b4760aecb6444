"""Wall time of ``agvdyn --help`` and ``agvdyn --version`` in fresh processes (issue 12: under 0.5 s).

    .venv/bin/python benchmarks/bench_startup.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path


def _command() -> list[str]:
    exe = Path(sys.executable).with_name("agvdyn")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("agvdyn")
    return [found] if found else [sys.executable, "-c", "from agvdyn.cli import main; main()"]


def wall(args: list[str], repeat: int) -> list[float]:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(_command() + args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    repeat = parser.parse_args().repeat
    wall(["--version"], 1)  # warm the file cache and the byte-code
    for args in (["--help"], ["--version"], ["identify", "--help"], ["batch", "--help"]):
        try:
            t = wall(args, repeat)
        except subprocess.CalledProcessError:
            print(f"agvdyn {' '.join(args):<18} failed")
            continue
        print(f"agvdyn {' '.join(args):<18} median {statistics.median(t):.3f} s  min {min(t):.3f} s  "
              f"max {max(t):.3f} s  ({repeat} runs)")


if __name__ == "__main__":
    main()
