"""Tree-engine figures (issue 2 targets). Run: `make bench` or `.venv/bin/python benchmarks/trees.py`.

Prints wall times (best of 3 fresh runs; caches cleared) for: enumerating all trees of order <= 16
with sigma and gamma; counting T_0 to order 18; the Butcher-form conditions of order <= 10 and
<= 12; and, where nodepy is importable, nodepy's Butcher-form strings of order <= 10 in the same
process. Also the whole-process time of `rkhp conditions --order 5 --degenerate` and `rkhp --help`.
"""

from __future__ import annotations

import subprocess
import sys
import time

from rkhp.trees import conditions
from rkhp.trees import rooted as trees


def best_of(fn, repeats=3):
    times = []
    for _ in range(repeats):
        trees._reset_tables()
        trees._counts.cache_clear()
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), result


def enumerate_16():
    return sum(1 for t in trees.trees_up_to(16) if t.sigma and t.gamma)


def count_t0_18():
    return [trees.count_trees(n, degenerate=True) for n in range(1, 19)]


def conditions_text(order):
    return [c.text() for c in conditions.order_conditions(order)]


def process_time(args, repeats=5):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "rkhp", *args], capture_output=True, check=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    rows = []
    t, n = best_of(enumerate_16)
    rows.append((f"enumerate T, order <= 16 ({n:,} trees, sigma, gamma)", t, "<= 1 s"))
    t, counts = best_of(count_t0_18)
    rows.append((f"count T_0 to order 18 (order 18: {counts[-1]:,})", t, ""))
    t, conds = best_of(lambda: conditions_text(10))
    ours_10 = t
    rows.append((f"Butcher-form conditions, order <= 10 ({len(conds):,})", t, "<= 0.1 s"))
    t, conds = best_of(lambda: conditions_text(12))
    rows.append((f"Butcher-form conditions, order <= 12 ({len(conds):,})", t, ""))
    try:
        import nodepy.rooted_trees as rt
        import nodepy.runge_kutta_method as rk
    except Exception as exc:  # nodepy is optional (extra `bench`)
        rows.append((f"nodepy not importable ({exc}; pip install -e '.[bench]')", float("nan"), ""))
    else:
        t0 = time.perf_counter()
        strings = [rk.elementary_weight_str(tree) for p in range(1, 11) for tree in rt.list_trees(p)]
        t = time.perf_counter() - t0
        rows.append((f"nodepy elementary_weight_str, order <= 10 ({len(strings):,})", t,
                     f"ratio nodepy/rkhp = {t / ours_10:.0f}x"))
    rows.append(("process: rkhp conditions --order 5 --degenerate", process_time(
        ["conditions", "--order", "5", "--degenerate"]), "<= 0.5 s"))
    rows.append(("process: rkhp --help", process_time(["--help"]), "<= 0.2 s"))
    width = max(len(r[0]) for r in rows)
    for label, seconds, note in rows:
        print(f"{label:<{width}}  {seconds:8.4f} s  {note}")


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/trees.py", __doc__).parse_args()
    main()
