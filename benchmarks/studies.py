"""Timing of the studies (issue 6 targets).

- `rkhp converge rigid-body` with defaults as a whole process: cold (empty numba cache, compile
  included; target <= 60 s on 2 cores) and warm (cache filled; target <= 10 s).
- Per-step cost of the classical peers (compiled loops) on the rigid body, after compilation.

Run: `.venv/bin/python benchmarks/studies.py` (prints measured figures; pins itself to 2 cores
where `taskset` exists, like CI).
"""

from __future__ import annotations

import os
import resource
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


def timed_process(args, env) -> tuple[float, float]:
    """(wall seconds, CPU seconds user + system) of one whole process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run(_cmd(args), env=env, capture_output=True, text=True, cwd=ROOT)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed: {result.stderr.strip()}")
    return seconds, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def converge_cold_warm(repeats: int = 3) -> None:
    """Cold: an empty numba cache (NUMBA_CACHE_DIR), so every kernel compiles; warm: cache filled.
    CPU time is printed too: on a shared machine the wall time grows with the load average."""
    args = ["converge", "rigid-body", "--format", "json"]
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        cold, cold_cpu = timed_process(args, env)
        warm = [timed_process(args, env) for _ in range(repeats)]
    wall = statistics.median(w for w, _ in warm)
    cpu = statistics.median(c for _, c in warm)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"rkhp converge rigid-body (defaults), whole process on 2 cores: cold {cold:.1f} s wall, "
          f"{cold_cpu:.1f} s CPU (target <= 60 s); warm median of {repeats}: {wall:.2f} s wall, {cpu:.2f} s CPU "
          f"(target <= 10 s)")


def peer_step_costs(steps: int = 20_000, repeats: int = 5) -> None:
    from rkhp.integrators.classical import integrate_classical, integrate_midpoint
    from rkhp.systems import get_system
    from rkhp.tableaux.files import load_tableau

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
    from work_precision import parser

    parser("python benchmarks/studies.py", __doc__).parse_args()
    converge_cold_warm()
    peer_step_costs()
