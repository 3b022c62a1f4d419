"""Cost of one RKHP Euler substep by each substep provider that takes it: the direct forms
(rkhp.integrators.closed_euler, rkhp.integrators.spray_euler) against the Taylor tower
(rkhp.integrators.tower_substep), each run by the driver's compiled loop (prints measured
figures; run: python benchmarks/substeps.py).

Cases: RKHP Euler and the triple jump tj4 of it on the rigid body (lie-poisson, so(3)*),
Lotka–Volterra (log-canonical) and the periodic Toda lattice of size 12 (lie-poisson, n = 24),
whose direct form is the closed one; on the planar charged particle, the Nambu system and the Toda
lattice of size 12 built in the general family (`as_general`: the spray realisation of a linear
pi), whose direct form is the spray's. For each: microseconds per Euler substep (the compiled
loop's own time divided by steps x substeps), warm (compiled before timing), the providers
alternating, minima over REPEATS runs; iterations per substep (chord iterations of a direct form,
Newton iterations of the tower); and the largest difference of the two trajectories over the
tower's steps, relative to the largest |y|.

Timed: `rkhp.integrators.driver.drive` called directly with its arguments built once (no Python
in the timed call), in CPU seconds of the calling thread (`time.thread_time`: on a shared machine
the time the other work takes from it is not counted; the minimum is then the fairer figure).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rkhp.integrators.driver import drive, record, run, setup
from rkhp.integrators.substeps import TOWER, choose
from rkhp.systems import get_system
from rkhp.systems.problems import as_general
from rkhp.tableaux.compositions import load_composition
from rkhp.tableaux.files import load_tableau

REPEATS = 7
CASES = (("rigid-body", "tj4", 0.1, 2000, 500), ("lotka-volterra", "tj4", 0.1, 2000, 500),
         ("toda:12", "tj4", 0.05, 1000, 50), ("charged-particle", "euler", 0.1, 2000, 100),
         ("nambu", "euler", 0.1, 2000, 100), ("toda:12 (general)", "euler", 0.1, 200, 10))
"""(system, method, h, steps of the direct form, steps of the tower) per case."""


def system_of(label: str):
    name = label.split()[0]
    return as_general(name) if label.endswith("(general)") else get_system(name)


def loop(system, provider, gammas, h: float, steps: int):
    """A call of the driver's compiled loop over `provider`'s substeps, its arguments built once."""
    ready = setup(system, load_tableau("euler"), gammas, provider=provider)
    y0, out = np.array(system.x0), record(steps, system.dim, True)
    return lambda: drive(y0, ready.gammas, h, steps, ready.data, ready.solver, out)


def seconds(call) -> float:
    """CPU seconds of this thread spent in one call."""
    t0 = time.thread_time()
    call()
    return time.thread_time() - t0


def measure(label: str, method: str, h: float, direct_steps: int, tower_steps: int) -> dict:
    system = system_of(label)
    gammas = (1.0,) if method == "euler" else load_composition(method).gamma_float
    s = len(gammas)
    euler = load_tableau("euler")
    direct = choose(system, euler).provider
    calls = {"direct": loop(system, direct, gammas, h, direct_steps),
             "tower": loop(system, TOWER, gammas, h, tower_steps)}
    times = {key: [] for key in calls}
    for call in calls.values():
        call()  # compile (or load the cache)
    for _ in range(REPEATS):
        for key, call in calls.items():
            times[key].append(seconds(call))
    fast = run(system, euler, h, direct_steps, gammas=gammas, provider=direct)
    slow = run(system, euler, h, tower_steps, gammas=gammas, provider=TOWER)
    gap = np.abs(fast.states[: tower_steps + 1] - slow.states).max() / np.abs(slow.states).max()
    return {
        "provider": direct.name,
        "direct_us": 1e6 * min(times["direct"]) / (direct_steps * s),
        "tower_us": 1e6 * min(times["tower"]) / (tower_steps * s),
        "iterations": float(np.mean(fast.newton_iterations)) / s,
        "tower_iterations": float(np.mean(slow.newton_iterations)) / s,
        "gap": float(gap),
    }


def main() -> None:
    print("$ python benchmarks/substeps.py")
    print(f"microseconds per Euler substep (min of {REPEATS}, thread CPU time)")
    print(f"{'system':<18} {'method':<6} {'h':>5} {'direct':>7} {'us':>7} {'tower us':>9} {'ratio':>7} "
          f"{'iter':>5} {'Newton':>6} {'rel diff':>9}")
    for case in CASES:
        m = measure(*case)
        label, method, h = case[:3]
        print(f"{label:<18} {method:<6} {h:>5g} {m['provider']:>7} {m['direct_us']:>7.2f} {m['tower_us']:>9.1f} "
              f"{m['tower_us'] / m['direct_us']:>6.1f}x {m['iterations']:>5.2f} "
              f"{m['tower_iterations']:>6.2f} {m['gap']:>9.1e}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
