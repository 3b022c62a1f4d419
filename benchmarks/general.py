"""Cost of the exact Poisson-spray realisation of the general family (issue 10; prints measured
figures; run: python benchmarks/general.py).

1. Rigid body, paper-three-stage at h = 0.1: us/step with the built-in closed form
   (docs/theory.md §4) and with the rigid body written as a general spec (the spray realisation,
   docs/theory.md §9.3), measured in the same run, alternately; the goal is <= 5x. so(3)* is
   linear, so the spray kernel sums its Bernoulli series; the same system with that mark taken
   off (`through_collocation`) shows what the Gauss collocation, the path of every pi that is not
   affine, costs on the same problem.
2. Where the time goes: one evaluation of alpha on the jets the step uses (degree D = 0..4 in
   3 variables), closed form against spray.
3. Growth with n on the periodic Toda lattice (n = 6, 12, 24): us/step of the closed form
   (Lie–Poisson, phi(K) x) and of the spray realisation.

CPU (process) seconds, minima over REPEATS alternating runs: on a shared machine the minimum is
the fairer figure.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from rkhp.integrators import integrate_rkhp
from rkhp.systems import get_system
from rkhp.systems.general import PoissonMatrix, general
from rkhp.systems.problems import as_general

REPEATS = 5
RIGID_BODY_POISSON = (("0", "-x3", "x2"), ("x3", "0", "-x1"), ("-x2", "x1", "0"))
RIGID_BODY_H = "x1^2/4 + x2^2/2 + 3*x3^2/4"


def rigid_body_general():
    """The rigid body in the general family (the matrix of so(3)*, the built-in's H and x0)."""
    from rkhp.base.expressions import parse_expression, variable_names
    from rkhp.systems.program import to_program
    from rkhp.systems.structure import symbols_of

    names = variable_names(3)
    entries = tuple(tuple(parse_expression(e, names) for e in row) for row in RIGID_BODY_POISSON)
    builtin = get_system("rigid-body")
    H = to_program(parse_expression(RIGID_BODY_H, names), symbols_of(3))
    return general(PoissonMatrix(entries), H, name="rigid-body-general", x0=builtin.x0,
                   t_final=10.0)


def through_collocation(system):
    """The system with its spray operations unmarked (float parameter 0.0, "X not affine in
    y"): the kernel then takes the Gauss collocation (docs/theory.md §9.3, "Choice of Q")."""
    from rkhp.taylor.ops import SPRAY

    def unmarked(tape):
        fpar = tape.fpar.copy()
        fpar[tape.ops[:, 0] == SPRAY] = 0.0
        return tape._replace(fpar=fpar)

    return dataclasses.replace(system, **{k: unmarked(getattr(system, k)) for k in
                                          ("h_tape", "f_tape", "alpha_tape", "beta_tape")})


def us_per_step(systems: dict, h: float, steps: int) -> dict:
    """CPU us/step of paper-three-stage for each system, minima over REPEATS alternating runs."""
    for s in systems.values():
        integrate_rkhp(s, "paper-three-stage", h, 2)  # compile / load the cache
    best = {k: np.inf for k in systems}
    for _ in range(REPEATS):
        for key, s in systems.items():
            c = time.process_time()
            traj = integrate_rkhp(s, "paper-three-stage", h, steps)
            assert traj.ok, traj.status
            best[key] = min(best[key], (time.process_time() - c) / steps * 1e6)
    return best


def alpha_cost_by_degree(closed, spray):
    """us per evaluation of the alpha tape on jets of degree D (3 variables, the step's space)."""
    import numba

    from rkhp.taylor.interpreter import address_of, as_plain, interpreter, run_from, tape_work
    from rkhp.taylor.jets import jet_space

    @numba.njit
    def loop(run, tape, D, space, work, count):
        tape_at, space_at, work_at = address_of(tape), address_of(space), address_of(work)
        for _ in range(count):
            run_from(run, tape_at, D, space_at, work_at)

    n, space = 3, jet_space(3, 4)
    rng = np.random.default_rng(1)
    x = np.array(closed.x0)
    p = 0.07 * rng.normal(size=n)
    rows = []
    for D in range(5):
        M = int(space.counts[D])
        dp = 0.02 * rng.normal(size=(n, M - 1))
        costs = []
        for system in (closed, spray):
            tape = system.alpha_tape
            work = tape_work((tape,), space.size)
            work.W[:n, 0], work.W[n:2 * n, 0] = x, p
            for k in range(n if D >= 1 else 0):
                work.W[k, 1 + k] = 1.0
            work.W[n:2 * n, 1:M] = dp
            run = interpreter(tape).address
            loop(run, as_plain(tape), np.int64(D), space, work, 1)
            best = np.inf
            for _ in range(REPEATS):
                c = time.process_time()
                loop(run, as_plain(tape), np.int64(D), space, work, 300)
                best = min(best, (time.process_time() - c) / 300 * 1e6)
            costs.append(best)
        rows.append((D, *costs))
    return rows


def main() -> None:
    print("1. rigid body, paper-three-stage, h = 0.1 (CPU us/step, min of "
          f"{REPEATS} alternating runs of 2000 steps)")
    closed, spray = get_system("rigid-body"), rigid_body_general()
    a = integrate_rkhp(closed, "paper-three-stage", 0.1, 100)
    b = integrate_rkhp(spray, "paper-three-stage", 0.1, 100)
    print(f"   100 steps: largest difference of the two trajectories "
          f"{np.abs(a.states - b.states).max():.1e}")
    t = us_per_step({"closed form": closed, "spray": spray,
                     "collocation": through_collocation(spray)}, 0.1, 2000)
    print(f"   closed form {t['closed form']:.1f} us/step, spray {t['spray']:.1f} us/step: "
          f"{t['spray'] / t['closed form']:.1f}x (goal <= 5x)")
    print(f"   through the collocation (pi not affine): {t['collocation']:.1f} us/step "
          f"({t['collocation'] / t['closed form']:.1f}x)")
    print("2. one evaluation of alpha on jets of degree D in 3 variables (CPU us)")
    for D, c, s in alpha_cost_by_degree(closed, spray):
        print(f"   D = {D}: closed form {c:.2f}, spray {s:.2f} ({s / c:.0f}x)")
    print("3. periodic Toda lattice, paper-three-stage, h = 0.1 (CPU us/step)")
    for n, steps in ((6, 200), (12, 20), (24, 2)):
        t = us_per_step({"closed form": get_system(f"toda:{n}"),
                         "spray": as_general(f"toda:{n}")}, 0.1, steps)
        print(f"   n = {n}: closed form {t['closed form']:.0f}, spray {t['spray']:.0f} "
              f"({t['spray'] / t['closed form']:.1f}x)")


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/general.py", __doc__).parse_args()
    main()
