"""Cost of one RKHP Euler substep on the spray realisation: the direct form
(rkhp.integrators.spray_euler) against the generic engine's Euler step (prints measured figures;
run: python benchmarks/spray_euler.py).

Systems of the general family: the planar charged particle and the Nambu system; and the periodic
Toda lattice of size 12 built in the general family (`as_general`: its own family is Lie–Poisson,
so this is the spray realisation of a linear pi). For each step h: microseconds per Euler substep
(the compiled loop's own time divided by the steps), warm (compiled before timing), the two
integrators alternating, minima over REPEATS runs; chord iterations per substep and nodes of the
direct form; and the largest difference of the two trajectories over the engine's steps.

Timed: each compiled loop called directly with its arguments built once (no Python in the timed
call), in CPU seconds of the calling thread (`time.thread_time`: on a shared machine the time the
other work takes from it is not counted; the minimum is then the fairer figure).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rkhp.integrators import engine, rkhp_method, spray_euler
from rkhp.integrators.newton import NEWTON_MAX_ITERATIONS, NEWTON_TOLERANCE
from rkhp.integrators.rkhp_method import integrate
from rkhp.integrators.spray_euler import integrate_spray_euler
from rkhp.systems import get_system
from rkhp.systems.problems import as_general

REPEATS = 7
STEPS = (("charged-particle", 2000, 100), ("nambu", 2000, 100), ("toda:12", 200, 10))
"""(system, steps of the direct form, steps of the engine) per run."""
H = (0.1, 0.01)


def system_of(name: str):
    return as_general(name) if name.startswith("toda") else get_system(name)


def direct_loop(system, h: float, steps: int):
    """A call of the direct form's compiled loop (`spray_euler.run`), its arguments built once."""
    n = system.dim
    tapes = spray_euler.spray_tapes(system)
    args = (np.array(system.x0), np.ones(1), h, steps, tapes, spray_euler.euler_work(tapes, n),
            spray_euler.substep_memory(1, n),
            engine.Solver(NEWTON_TOLERANCE, NEWTON_MAX_ITERATIONS, system.domain_code),
            engine.Record(np.zeros((steps + 1, n)), np.zeros(steps, np.int64), True))
    return lambda: spray_euler.run(*args)


def engine_loop(system, h: float, steps: int):
    """A call of the engine's compiled loop (`engine.rkhp_run`) with the Euler tableau, as
    `rkhp.integrators.rkhp_method.integrate` makes it."""
    tableau = rkhp_method.resolve_tableau("euler")
    A, b = rkhp_method.tableau_arrays(tableau)
    stage = rkhp_method.stage_solve(tableau, A)
    tapes, interpreter, space = rkhp_method.engine_data(system, len(b), stage)
    n = system.dim
    args = (np.array(system.x0), engine.Method(A, b, h), steps, interpreter.address, tapes, space,
            engine.step_buffers(tapes, n, len(b), space),
            engine.Solver(NEWTON_TOLERANCE, NEWTON_MAX_ITERATIONS, system.domain_code),
            rkhp_method.compiled_stage(stage),
            engine.Record(np.zeros((steps + 1, n)), np.zeros(steps, np.int64), True, np.zeros(steps, np.int64)))
    return lambda: engine.rkhp_run(*args)


def seconds(call) -> float:
    """CPU seconds of this thread spent in one call."""
    t0 = time.thread_time()
    call()
    return time.thread_time() - t0


def measure(name: str, direct_steps: int, engine_steps: int, h: float) -> dict:
    system = system_of(name)
    direct, engine_run = direct_loop(system, h, direct_steps), engine_loop(system, h, engine_steps)
    direct(), engine_run()  # compile (or load the cache)
    times = {"direct": [], "engine": []}
    for _ in range(REPEATS):
        times["direct"].append(seconds(direct))
        times["engine"].append(seconds(engine_run))
    run = integrate_spray_euler(system, (1.0,), h, direct_steps)
    gap = np.abs(run.states[: engine_steps + 1]
                 - integrate(system, "euler", h, engine_steps).states).max()
    return {
        "direct_us": 1e6 * min(times["direct"]) / direct_steps,
        "engine_us": 1e6 * min(times["engine"]) / engine_steps,
        "iterations": float(np.mean(run.newton_iterations)),
        "nodes": run.extra["nodes"][0],
        "gap": float(gap),
    }


def main() -> None:
    print("$ python benchmarks/spray_euler.py")
    print(f"{'system':<18} {'h':>5} {'direct us':>10} {'engine us':>10} {'ratio':>7} "
          f"{'iter':>5} {'Q':>3} {'max |diff|':>11}")
    for name, direct_steps, engine_steps in STEPS:
        label = name + (" (general)" if name.startswith("toda") else "")
        for h in H:
            m = measure(name, direct_steps, engine_steps, h)
            print(f"{label:<18} {h:>5g} {m['direct_us']:>10.2f} {m['engine_us']:>10.1f} "
                  f"{m['engine_us'] / m['direct_us']:>6.1f}x {m['iterations']:>5.2f} "
                  f"{m['nodes']:>3d} {m['gap']:>11.1e}")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
