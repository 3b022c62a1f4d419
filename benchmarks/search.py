"""Benchmark of `rkhp search`: time to the first verified solution and success rate per restart.

Targets (issue 4): degenerate order 4 with 3 stages <= 1 s; degenerate order 5 at its minimal
stage count (4) <= 10 s; general order 5 with 6 stages <= 30 s.

For each problem: the wall time of ``search(..., order=N)`` until the first solution verified by
``rkhp.tableaux.verification`` at 30 digits (without and with closed-form recognition, which ends in an exact
verification), over several seeds (median and max), and the success rate of the restarts
(``run_restarts`` with no early stop). One worker; imports and the first call's set-up are warmed
up before timing. Run: ``.venv/bin/python benchmarks/search.py [--quick]``.
"""

from __future__ import annotations

import statistics
import time

from rkhp.search.driver import SearchOptions, search
from rkhp.search.multistart import Problem, run_restarts

PROBLEMS = [  # (stages, order, class, target seconds)
    (3, 4, "degenerate", 1.0),
    (4, 5, "degenerate", 10.0),
    (6, 5, "general", 30.0),
]


def time_to_first(stages: int, order: int, cls: str, seed: int, closed: bool) -> tuple[float, bool]:
    t0 = time.perf_counter()
    result = search(stages, order, cls, options=SearchOptions(restarts=200, seed=seed,
                                                              closed_form=closed))
    return time.perf_counter() - t0, result.found is not None


def main() -> None:
    from work_precision import parser

    p = parser("python benchmarks/search.py", __doc__)
    p.add_argument("--quick", action="store_true", help="3 seeds, 10 restarts for the rates")
    quick = p.parse_args().quick
    seeds = range(3 if quick else 5)
    rate_restarts = 10 if quick else 40
    search(2, 3, "degenerate", options=SearchOptions(restarts=5))  # warm-up: imports, caches
    print(f"{'problem':<28} {'target':>7} {'first verified (30 digits)':>28} "
          f"{'first exact (closed form)':>27} {'success/restart':>16} {'s/restart':>10}")
    for stages, order, cls, target in PROBLEMS:
        plain = [time_to_first(stages, order, cls, seed, False) for seed in seeds]
        exact = [time_to_first(stages, order, cls, seed, True) for seed in seeds]
        run = run_restarts(Problem(stages, order, cls), rate_restarts, seed=100, stop_after=None)
        rate = len(run.successes) / len(run.attempts)
        per = run.seconds / len(run.attempts)

        def fmt(rows):
            times = [t for t, ok in rows]
            ok = sum(ok for _, ok in rows)
            return f"med {statistics.median(times):5.2f} max {max(times):5.2f} ({ok}/{len(rows)})"

        name = f"{cls} order {order}, {stages} stages"
        print(f"{name:<28} {target:>6.0f}s {fmt(plain):>28} {fmt(exact):>27} "
              f"{len(run.successes):>3}/{len(run.attempts):<3} ({rate:4.0%}) {per:9.3f}s")


if __name__ == "__main__":
    main()
