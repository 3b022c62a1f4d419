"""Timing of the studies (issue 6 targets).

- `rkhp converge rigid-body` with defaults as a whole process: cold (empty numba cache, compile
  included; target <= 60 s on 2 cores) and warm (cache filled; target <= 10 s).
- Per-step cost of the classical peers (compiled loops) on the rigid body, after compilation.

Run: `.venv/bin/python benchmarks/studies.py` (prints measured figures; pins itself to 2 cores
where `taskset` exists, like CI).
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RKHP = [str(Path(sys.executable).parent / "rkhp")]


def _cmd(args):
    pin = ["taskset", "-c", "0,1"] if shutil.which("taskset") and (os.cpu_count() or 1) >= 2 else []
    return pin + RKHP + args


def timed_process(args, env) -> float:
    start = time.perf_counter()
    result = subprocess.run(_cmd(args), env=env, capture_output=True, text=True, cwd=ROOT)
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed: {result.stderr.strip()}")
    return seconds


def converge_cold_warm(repeats: int = 3) -> None:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        cold = timed_process(["converge", "rigid-body", "--format", "json"], env)
        warm = [timed_process(["converge", "rigid-body", "--format", "json"], env) for _ in range(repeats)]
    print(f"rkhp converge rigid-body (defaults), whole process, 2 cores: cold {cold:.1f} s (target <= 60), "
          f"warm median {statistics.median(warm):.2f} s of {repeats} (target <= 10)")


def peer_step_costs(steps: int = 20_000, repeats: int = 5) -> None:
    from rkhp.integrators.classical import integrate_classical, integrate_midpoint
    from rkhp.systems import get_system
    from rkhp.tablefiles import load_tableau

    rigid = get_system("rigid-body")
    rk4 = load_tableau("rk4")
    first = integrate_classical(rigid, rk4, 0.01, 10)
    mid = integrate_midpoint(rigid, 0.01, 10)
    rk = statistics.median(integrate_classical(rigid, rk4, 0.01, steps).run_seconds for _ in range(repeats))
    md = statistics.median(integrate_midpoint(rigid, 0.01, steps).run_seconds for _ in range(repeats))
    print(f"classical rk4 on the rigid body: {rk / steps * 1e6:.2f} us/step (median of {repeats} x {steps} steps; "
          f"compile or cache load {first.compile_seconds:.2f} s)")
    print(f"implicit midpoint on the rigid body: {md / steps * 1e6:.2f} us/step, h = 0.01 "
          f"(compile or cache load {mid.compile_seconds:.2f} s)")


if __name__ == "__main__":
    converge_cold_warm()
    peer_step_costs()
