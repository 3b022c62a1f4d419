"""Benchmark of the executors (docs/distributed.md): restarts per second of the order-7 search
in one process, on 2 local worker processes and on a Dask cluster of 2 workers, and the per-task
overhead of each, measured in one run; then the projected speed-up of a 100-worker cluster.

The search is degenerate order 7 with 7 explicit stages (issue 16 (b)); every configuration runs
the same restarts (indices 0..R-1, no early stop), so the work is identical and the results are
checked equal. The per-task overhead is the wall time per task of R_EMPTY empty tasks submitted
at once (submission, scheduling, transfer of the result). The cluster is `dask scheduler` and two
`dask worker --nthreads 1 --no-nanny` processes on 127.0.0.1 (rkhp.executors.loopback_cluster).

Projection (labelled as such in the output): a 100-worker cluster runs restarts at
100 x (2-worker cluster rate / 2), capped by the scheduler's task rate 1 / overhead; the speed-up is
that over the one-process rate. It assumes workers like these (same per-restart time), restarts
independent (they are) and enough restarts to keep every worker busy.

Run: ``.venv/bin/python benchmarks/distributed.py [--restarts R]`` (default 12). The figures
depend on the machine's load: the load average is printed with them.
"""

from __future__ import annotations

import argparse
import os
import time

from rkhp.executors import InProcess, LocalProcesses, loopback_cluster, make_executor, run_all
from rkhp.search.multistart import Problem, run_restarts

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
    one, cluster_rate, cluster_overhead = rows[0][1], rows[2][1], rows[2][2]
    per_worker = cluster_rate / 2
    projected = min(PROJECTED_WORKERS * per_worker, 1 / cluster_overhead)
    print(f"PROJECTION (not a measurement): {PROJECTED_WORKERS} workers like these x {per_worker:.3f} restarts/s "
          f"each = {PROJECTED_WORKERS * per_worker:.1f} restarts/s, scheduler cap 1/overhead = "
          f"{1 / cluster_overhead:.0f} tasks/s -> {projected:.1f} restarts/s, speed-up {projected / one:.0f}x "
          f"over one process on the order-7 search")
    print(f"load average at end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
