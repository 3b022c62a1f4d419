"""Cost of one RKHP Euler substep on the spray realisation: the direct form
(rkhp.integrators.spray_euler) against the generic engine's Euler step (prints measured figures;
run: python benchmarks/spray_euler.py).

Systems of the general family: the planar charged particle and the Nambu system; and the periodic
Toda lattice of size 12 built in the general family (`as_general`: its own family is Lie–Poisson,
so this is the spray realisation of a linear pi). For each step h: microseconds per Euler substep
(the compiled loop's own time, `Trajectory.run_seconds`, divided by the steps), warm (compiled
before timing), the two integrators alternating, minima over REPEATS runs (on a shared machine the
minimum is the fairer figure); chord iterations per substep and nodes of the direct form; and the
largest difference of the two trajectories over the engine's steps.
"""

from __future__ import annotations

import sys

import numpy as np

from rkhp.integrators import integrate
from rkhp.integrators.spray_euler import integrate_spray_euler
from rkhp.systems import get_system
from rkhp.systems.problems import as_general

REPEATS = 5
STEPS = (("charged-particle", 2000, 100), ("nambu", 2000, 100), ("toda:12", 200, 10))
"""(system, steps of the direct form, steps of the engine) per run."""
H = (0.1, 0.01)


def system_of(name: str):
    return as_general(name) if name.startswith("toda") else get_system(name)


def measure(name: str, direct_steps: int, engine_steps: int, h: float) -> dict:
    system = system_of(name)
    direct_runs, engine_runs = [], []
    for _ in range(REPEATS + 1):  # the first of each compiles (or loads the cache): not counted
        direct_runs.append(integrate_spray_euler(system, (1.0,), h, direct_steps))
        engine_runs.append(integrate(system, "euler", h, engine_steps))
    direct, engine = direct_runs[-1], engine_runs[-1]
    gap = np.abs(direct.states[: engine_steps + 1] - engine.states).max()
    return {
        "direct_us": 1e6 * min(r.run_seconds for r in direct_runs[1:]) / direct_steps,
        "engine_us": 1e6 * min(r.run_seconds for r in engine_runs[1:]) / engine_steps,
        "iterations": float(np.mean(direct.newton_iterations)),
        "nodes": direct.extra["nodes"][0],
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
