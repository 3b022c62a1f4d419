"""Cost of deriving the symmetric relations (issue 7). Run: `.venv/bin/python benchmarks/relations.py`.

Prints, for orders 6, 7, 8: the wall time of the constant-pi evaluation (dimension 6, one prime,
all T_0 trees of order <= N on |T_0(N)| + 10 random instances), of the Lie–Poisson so(3)*
evaluation, and of the whole `derive_relations(N)` (three primes, exact check, cross-check); then
the peak resident memory of the process. Each figure is one run (the derivation is deterministic).
"""

from __future__ import annotations

import resource
import time

import numpy as np

from rkhp.base.modular import PRIMES
from rkhp.series.differentials import constant_pi_values, general_values
from rkhp.series.relation_derivation import derive_relations
from rkhp.trees.rooted import trees_of_order


def timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - t0, out


def main() -> None:
    print("order  T_0(N)  instances  constant-pi [s]  so(3)* [s]  derive_relations [s]  relations  conditions")
    for n in (6, 7, 8):
        trees = [t for m in range(1, n + 1) for t in trees_of_order(m, True)]
        batch = len(trees_of_order(n, True)) + 10
        t_const, _ = timed(constant_pi_values, trees, n, 6, batch, np.random.default_rng(0), PRIMES[0])
        t_lp, _ = timed(general_values, trees, n, "lie-poisson", batch, np.random.default_rng(0), PRIMES[0])
        t_all, data = timed(derive_relations, n, seed=0)
        top = data.of_order(n)
        print(f"{n:5d}  {len(top.trees):6d}  {batch:9d}  {t_const:15.2f}  {t_lp:10.2f}  {t_all:20.2f}  "
              f"{len(top.relations):9d}  {len(top.conditions):10d}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MiB")


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/relations.py", __doc__).parse_args()
    main()
