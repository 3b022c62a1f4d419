"""Implicit RKHP methods (issue 13; docs/implicit.md). Prints measured figures; run:
python benchmarks/implicit.py [PLOT] (PLOT: the work-precision figure, default
implicit-work-precision.png).

1. Rigid body, h = 0.1: us/step of gauss2 and paper-implicit against the explicit
   paper-three-stage, in this run (goal: gauss2 <= 3x), with Newton iterations and stage sweeps.
2. The stage solve, Picard sweeps against Newton's method on the coefficients of the stage
   polynomials: per step, the measured Picard cost and sweeps, against what one Newton iteration
   on the s n C(n + D - 1, n) coefficients costs at least: the dense LU factorisation (exact
   Newton) or one solve with a factorisation kept from earlier steps (simplified Newton), timed
   on matrices of that size in this run; the Jacobian's assembly is not even counted.
3. Work-precision on the rigid body (T = 10) with `rkhp bench`'s study: wall time against error
   for paper-three-stage, gauss2, gauss3 and paper-implicit; the plot is written to PLOT.

CPU (process) times, minima over REPEATS: on a loaded machine they are the fairer figure.
"""

from __future__ import annotations

import os
import sys
import time
from math import comb

import numpy as np
import scipy.linalg

from rkhp.integrators import integrate_rkhp
from rkhp.integrators.methods import resolve_method
from rkhp.integrators.tower_substep import stage_solve, tableau_arrays
from rkhp.systems import get_system

REPEATS = 5
STEPS = 1000


def per_step(system, method, h, steps=STEPS):
    """(us/step CPU, mean Newton iterations, mean stage sweeps), the best of REPEATS runs."""
    integrate_rkhp(system, method, h, 2)
    best, run = np.inf, None
    for _ in range(REPEATS):
        c = time.process_time()
        run = integrate_rkhp(system, method, h, steps).raise_if_failed()
        best = min(best, time.process_time() - c)
    sweeps = float(np.mean(run.stage_sweeps)) if run.stage_sweeps.size else 0.0
    return best / steps * 1e6, float(np.mean(run.newton_iterations)), sweeps


def lu_seconds(size: int):
    """(factorisation, one solve) CPU seconds for a dense size x size system, minima of REPEATS."""
    rng = np.random.default_rng(0)
    M = rng.normal(size=(size, size)) / size + np.eye(size)
    r = rng.normal(size=size)
    fac, sol = np.inf, np.inf
    for _ in range(REPEATS):
        c = time.process_time()
        for _ in range(10):
            lu = scipy.linalg.lu_factor(M)
        fac = min(fac, (time.process_time() - c) / 10)
        c = time.process_time()
        for _ in range(100):
            scipy.linalg.lu_solve(lu, r)
        sol = min(sol, (time.process_time() - c) / 100)
    return fac, sol


def coefficients(system, method) -> tuple[int, int]:
    """(stage degree D, unknowns s n C(n + D - 1, n) of Newton's method on the coefficients)."""
    tableau = resolve_method(method).tableau
    A, b = tableau_arrays(tableau)
    degree = stage_solve(tableau, A).degree
    n = system.dim
    return degree, len(b) * n * comb(n + degree - 1, n)


def main(argv) -> None:
    from work_precision import parser

    from rkhp.studies.plots import check_plot_path

    p = parser("python benchmarks/implicit.py", __doc__)
    p.add_argument("plot", nargs="?", default="implicit-work-precision.png", metavar="PLOT",
                   help="the work-precision figure")
    plot = check_plot_path(p.parse_args(argv).plot, force=True)  # before the work: a bad name fails first
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    rb = get_system("rigid-body")
    explicit, newton, _ = per_step(rb, "paper-three-stage", 0.1)
    print(f"[1] rigid body, h = 0.1: paper-three-stage {explicit:.1f} us/step CPU "
          f"(Newton {newton:.2f}/step)")
    for method in ("gauss2", "paper-implicit"):
        us, newton, sweeps = per_step(rb, method, 0.1)
        print(f"[1] rigid body, h = 0.1: {method} {us:.1f} us/step CPU = {us / explicit:.2f} x "
              f"paper-three-stage (Newton {newton:.2f}, sweeps {sweeps:.2f} per step"
              f"{'; goal <= 3x' if method == 'gauss2' else ''})")

    for name, h in (("rigid-body", 0.1), ("rigid-body", 0.01), ("lotka-volterra", 0.1),
                    ("lotka-volterra", 0.01)):
        system = get_system(name)
        degree, unknowns = coefficients(system, "gauss2")
        us, _, sweeps = per_step(system, "gauss2", h)
        fac, sol = lu_seconds(unknowns)
        print(f"[2] {name}, gauss2, h = {h}: Picard {us:.1f} us/step CPU with {sweeps:.2f} "
              f"sweeps/step ({us / sweeps:.1f} us/sweep incl. Newton); Newton on the "
              f"{unknowns} coefficients (D = {degree}): LU {fac * 1e6:.0f} us, one solve "
              f"{sol * 1e6:.1f} us per iteration")

    from rkhp.studies.bench import bench
    from rkhp.studies.plots import plot_work_precision

    study = bench(rb, ["paper-three-stage", "gauss2", "gauss3", "paper-implicit"], peers=(),
                  steps=(10, 20, 40, 80, 160, 320, 640, 1280), repeats=REPEATS)
    for curve in study.curves:
        points = ", ".join(f"{p.steps}: {p.error:.1e} in {p.seconds * 1e3:.2f} ms"
                           for p in curve.points if p.error is not None)
        print(f"[3] {curve.method}: {points}")
    print(f"[3] plot: {plot_work_precision(study, plot, force=True)}")


if __name__ == "__main__":
    from work_precision import run_script

    run_script(main, sys.argv[1:])
