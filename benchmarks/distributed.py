"""Benchmark of the executors (docs/distributed.md): restarts per second of the order-7 search
in one process, on 2 local worker processes and on a Dask cluster of 2 workers, and the per-task
overhead of each, measured in one run; then the projected speed-up of a 100-worker cluster.

The search is degenerate order 7 with 7 explicit stages (issue 16 (b)); every configuration runs
the same restarts (indices 0..R-1, no early stop), so the work is identical and the results are
checked equal. The per-task overhead is the wall time per task of R_EMPTY empty tasks submitted
at once (submission, scheduling, transfer of the result). The cluster is `dask scheduler` and two
`dask worker --nthreads 1 --no-nanny` processes on 127.0.0.1 (rkhp.base.executors.loopback_cluster).

Projection (labelled as such in the output): a 100-worker cluster runs restarts at
100 x (one-process rate) x t / (t + overhead), t the time of one restart, capped by the task rate
1 / overhead measured here; the speed-up is that over the one-process rate. It assumes workers on
dedicated cores as fast as this one, restarts independent (they are) and enough restarts to keep
every worker busy. A second figure scales the rate per worker measured on the 2-worker cluster
(on a shared machine, that rate carries the machine's load).

Run: ``.venv/bin/python benchmarks/distributed.py [--restarts R]`` (default 12). The figures
depend on the machine's load: the load average is printed with them.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

# Run as a script, this file's folder comes first on sys.path and its name would hide the
# `distributed` package that Dask needs: take the folder off.
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(os.path.abspath(__file__))]

from rkhp.base.executors import InProcess, LocalProcesses, loopback_cluster, make_executor, run_all  # noqa: E402
from rkhp.search.multistart import Problem, run_restarts  # noqa: E402

PROBLEM = Problem(7, 7, "degenerate")
R_EMPTY = 200
PROJECTED_WORKERS = 100


def empty() -> None:
    """An empty task (measures the executor's own cost)."""


def measure(executor, restarts: int):
    """(restarts per second, seconds per empty task, the restarts' end points) on ``executor``."""
    run_all(executor, empty, [()] * (2 * executor.slots))  # warm-up: workers started, modules imported
    run_restarts(PROBLEM, executor.slots, seed=99, executor=executor, stop_after=None)  # warm-up: system built
    t0 = time.perf_counter()
    run = run_restarts(PROBLEM, restarts, seed=0, executor=executor, stop_after=None)
    rate = len(run.attempts) / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    run_all(executor, empty, [()] * R_EMPTY)
    overhead = (time.perf_counter() - t0) / R_EMPTY
    return rate, overhead, [a.x for a in run.attempts]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--restarts", type=int, default=12)
    restarts = parser.parse_args().restarts
    print(f"problem: degenerate order 7, 7 explicit stages; {restarts} restarts per configuration; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start")
    rows = []
    single = InProcess()
    rows.append(("1 process", *measure(single, restarts)))
    pool = LocalProcesses(2)
    try:
        rows.append(("2 local worker processes", *measure(pool, restarts)))
    finally:
        pool.close()
    with loopback_cluster(2) as cluster:
        dask = make_executor(scheduler=cluster.address)
        try:
            rows.append(("Dask cluster, 2 workers", *measure(dask, restarts)))
        finally:
            dask.close()
    reference = rows[0][3]
    print(f"{'executor':<28} {'restarts/s':>11} {'speed-up':>9} {'overhead/task':>14} {'same results':>13}")
    for name, rate, overhead, points in rows:
        print(f"{name:<28} {rate:11.3f} {rate / rows[0][1]:8.2f}x {overhead * 1e3:11.2f} ms "
              f"{'yes' if points == reference else 'NO':>13}")
    one, cluster_rate, overhead = rows[0][1], rows[2][1], rows[2][2]
    per_restart = 1 / one
    efficiency = per_restart / (per_restart + overhead)
    cap = 1 / overhead
    dedicated = min(PROJECTED_WORKERS * one * efficiency, cap)
    measured = min(PROJECTED_WORKERS * cluster_rate / 2, cap)
    print(f"PROJECTION (not a measurement) for {PROJECTED_WORKERS} workers on the order-7 search:")
    print(f"  workers on dedicated cores: each {per_restart:.3f} s per restart + {overhead * 1e3:.1f} ms per task "
          f"(efficiency {efficiency:.3f}), capped at 1/overhead = {cap:.0f} tasks/s -> {dedicated:.1f} restarts/s, "
          f"speed-up {dedicated / one:.0f}x over one process")
    print(f"  workers as loaded as these two ({cluster_rate / 2:.3f} restarts/s each) -> {measured:.1f} restarts/s, "
          f"speed-up {measured / one:.0f}x")
    print(f"load average at end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
