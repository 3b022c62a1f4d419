"""Cost of one RKHP Euler substep on the closed-form families: the direct form
(rkhp.integrators.closed_euler) against the generic engine's composed loop
(rkhp.integrators.composed), inside the triple jump tj4 (prints measured figures; run:
python benchmarks/closed_euler.py).

Systems: the rigid body (lie-poisson, so(3)*), Lotka–Volterra (log-canonical) and the periodic
Toda lattice of size 12 (lie-poisson, n = 24). For each: microseconds per Euler substep (the
compiled loop's own time divided by steps x 3 substeps), warm (compiled before timing), the two
loops alternating, minima over REPEATS runs; chord iterations per substep of the direct form and
Newton iterations per substep of the engine; and the largest difference of the two trajectories
over the engine's steps, relative to the largest |y|.

Timed: each compiled loop called directly with its arguments built once (no Python in the timed
call), in CPU seconds of the calling thread (`time.thread_time`: on a shared machine the time the
other work takes from it is not counted; the minimum is then the fairer figure).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rkhp.integrators import closed_euler, composed, engine, rkhp_method
from rkhp.integrators.closed_euler import integrate_closed_euler
from rkhp.integrators.composed import integrate_composition
from rkhp.integrators.newton import NEWTON_MAX_ITERATIONS, NEWTON_TOLERANCE
from rkhp.systems import get_system
from rkhp.tableaux.compositions import load_composition

REPEATS = 7
COMPOSITION = "tj4"
CASES = (("rigid-body", 0.1, 2000, 500), ("lotka-volterra", 0.1, 2000, 500),
         ("toda:12", 0.05, 1000, 50))
"""(system, h, steps of the direct form, steps of the engine) per run."""


def direct_loop(system, gammas, h: float, steps: int):
    """A call of the direct form's compiled loop (`closed_euler.run`), its arguments built once."""
    n = system.dim
    form = closed_euler.closed_form(system)
    args = (np.array(system.x0), np.array(gammas), h, steps, form, closed_euler.closed_work(form, n),
            closed_euler.chord_memory(len(gammas), n),
            composed.Solver(NEWTON_TOLERANCE, NEWTON_MAX_ITERATIONS, system.domain_code),
            composed.Record(np.zeros((steps + 1, n)), np.zeros(steps, np.int64), True))
    return lambda: closed_euler.run(*args)


def engine_loop(system, gammas, h: float, steps: int):
    """A call of the engine's composed loop (`composed.composed_run`) over the Euler tableau, as
    `rkhp.integrators.composed.integrate_composition` makes it."""
    tableau = rkhp_method.resolve_tableau("euler")
    A, b = rkhp_method.tableau_arrays(tableau)
    tapes, interpreter, space = rkhp_method.engine_data(system, len(b), rkhp_method.stage_solve(tableau, A))
    n = system.dim
    args = (np.array(system.x0), composed.Substeps(A, b, h * np.array(gammas)), steps, interpreter.address,
            tapes, space,
            engine.step_buffers(tapes, n, len(b), space),
            composed.substep_memory(len(gammas), n),
            composed.Solver(NEWTON_TOLERANCE, NEWTON_MAX_ITERATIONS, system.domain_code),
            composed.Record(np.zeros((steps + 1, n)), np.zeros(steps, np.int64), True))
    return lambda: composed.composed_run(*args)


def seconds(call) -> float:
    """CPU seconds of this thread spent in one call."""
    t0 = time.thread_time()
    call()
    return time.thread_time() - t0


def measure(name: str, h: float, direct_steps: int, engine_steps: int) -> dict:
    system = get_system(name)
    composition = load_composition(COMPOSITION)
    gammas = composition.gamma_float
    s = len(gammas)
    direct, engine_run = direct_loop(system, gammas, h, direct_steps), engine_loop(system, gammas, h, engine_steps)
    direct(), engine_run()  # compile (or load the cache)
    times = {"direct": [], "engine": []}
    for _ in range(REPEATS):
        times["direct"].append(seconds(direct))
        times["engine"].append(seconds(engine_run))
    run = integrate_closed_euler(system, gammas, h, direct_steps)
    reference = integrate_composition(system, composition, h, engine_steps)
    gap = np.abs(run.states[: engine_steps + 1] - reference.states).max() / np.abs(reference.states).max()
    return {
        "direct_us": 1e6 * min(times["direct"]) / (direct_steps * s),
        "engine_us": 1e6 * min(times["engine"]) / (engine_steps * s),
        "iterations": float(np.mean(run.newton_iterations)) / s,
        "engine_iterations": float(np.mean(reference.newton_iterations)) / s,
        "gap": float(gap),
    }


def main() -> None:
    print("$ python benchmarks/closed_euler.py")
    print(f"{COMPOSITION}: microseconds per Euler substep (min of {REPEATS}, thread CPU time)")
    print(f"{'system':<16} {'h':>5} {'direct us':>10} {'engine us':>10} {'ratio':>7} "
          f"{'iter':>5} {'Newton':>6} {'rel diff':>9}")
    for name, h, direct_steps, engine_steps in CASES:
        m = measure(name, h, direct_steps, engine_steps)
        print(f"{name:<16} {h:>5g} {m['direct_us']:>10.2f} {m['engine_us']:>10.1f} "
              f"{m['engine_us'] / m['direct_us']:>6.1f}x {m['iterations']:>5.2f} "
              f"{m['engine_iterations']:>6.2f} {m['gap']:>9.1e}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
