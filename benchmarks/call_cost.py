"""What a call of the integrators costs over its compiled loop (docs/engine.md "One driver, many
substeps": a system is built once, a method resolved once, a provider's data prepared once).

Run: python benchmarks/call_cost.py [--rounds N] [CASE ...]   (a case: SYSTEM/METHOD/H/STEPS)

For each case, three calls that compute the same trajectory, interleaved in rounds, warm (each
called before the rounds), timed by the CPU time of the calling thread (`time.thread_time`: on a
shared machine the time other work takes from it is not counted), the minimum over the rounds:

- by name: ``rkhp.integrate(SYSTEM, METHOD, H, STEPS)``, as documented;
- resolved: ``method.integrate(system, H, STEPS)`` with the system and the method resolved once;
- with x0: ``method.integrate(system, H, STEPS, x0)``, the start given (as a study gives it);
- loop: the compiled loop alone, `rkhp.integrators.driver.drive`'s compiled entry point for the
  run's types (`driver.compiled_loop`: no dispatcher) with its arguments prepared once (the
  provider's data, the solver, the record it writes).

It prints microseconds per call, the cost of each call over the loop, and whether the four
computed the same final state bit for bit. Then an ensemble: the final states of K starts near
the system's start by K calls of ``method.integrate``, and by one `Method.integrate_ensemble`
call on one thread and on the threads available (CPU time of the process, all its threads, and
wall time; minima over rounds), and whether the ensemble's final states are those of one run at
a time bit for bit.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import rkhp
from rkhp.integrators import driver
from rkhp.integrators.methods import resolve_method, resolve_system

CASES = ("charged-particle/kahan-li8/0.1/10", "charged-particle/kahan-li8/0.1/1", "rigid-body/kahan-li8/0.1/10",
         "rigid-body/kahan-li8/0.1/1", "rigid-body/rk4/0.1/10",
         "nambu/sofroniou-spaletta10/0.1/10", "toda:12/kahan-li8/0.1/10")
ROUNDS = 40
ENSEMBLE = 64


def calls(system_name: str, method_name: str, h: float, steps: int) -> dict:
    """The three calls of a case (see the module), each returning its final state."""
    system, method = resolve_system(system_name), resolve_method(method_name)
    gammas = (1.0,) if method.kind == "rkhp" else method.composition.gamma_float
    ready = driver.setup(system, method.tableau, gammas)
    y0, out = system.start(), driver.record(steps, system.dim, True)
    args = (y0, ready.gammas, 0, h, steps, ready.data, ready.solver, out)
    driver.drive(*args)
    entry = driver.compiled_loop(args)

    def by_name():
        return rkhp.integrate(system_name, method_name, h, steps).final_state

    def resolved():
        return method.integrate(system, h, steps).final_state

    def with_x0():
        return method.integrate(system, h, steps, y0).final_state

    def loop():
        entry(*args)
        return out.states[-1]

    return {"by name": by_name, "resolved": resolved, "with x0": with_x0, "loop": loop}


def least_cpu(contenders: dict, rounds: int) -> tuple[dict, dict]:
    """(minimum thread CPU seconds, last result) per contender, interleaved in rounds, warm."""
    results = {key: call() for key, call in contenders.items()}
    best = dict.fromkeys(contenders, float("inf"))
    for _ in range(rounds):
        for key, call in contenders.items():
            t0 = time.thread_time()
            results[key] = call()
            best[key] = min(best[key], time.thread_time() - t0)
    return best, results


def per_call(cases, rounds: int) -> None:
    print(f"microseconds per call (thread CPU time, minimum of {rounds} interleaved rounds, warm)")
    print(f"{'case':42s} {'by name':>9s} {'resolved':>9s} {'with x0':>9s} {'loop':>9s} {'name-loop':>10s} "
          f"{'resolved-loop':>14s} {'x0-loop':>8s}  same")
    for case in cases:
        name, method, h, steps = case.split("/")
        best, results = least_cpu(calls(name, method, float(h), int(steps)), rounds)
        us = {key: 1e6 * value for key, value in best.items()}
        same = all(np.array_equal(results["loop"], r) for r in results.values())
        print(f"{case:42s} {us['by name']:9.1f} {us['resolved']:9.1f} {us['with x0']:9.1f} {us['loop']:9.1f} "
              f"{us['by name'] - us['loop']:10.1f} {us['resolved'] - us['loop']:14.1f} "
              f"{us['with x0'] - us['loop']:8.1f}  {same}")


def ensemble(case: str, k: int, rounds: int) -> None:
    name, method_name, h, steps = case.split("/")
    h, steps = float(h), int(steps)
    system, method = resolve_system(name), resolve_method(method_name)
    starts = system.x0 * (1.0 + 0.05 * np.random.default_rng(0).standard_normal((k, system.dim)))
    one = np.array([method.integrate(system, h, steps, x0=x).final_state for x in starts])
    many = method.integrate_ensemble(system, h, steps, starts)
    best = {"one at a time": [float("inf")] * 2, "in one call, 1 thread": [float("inf")] * 2,
            "in one call, threads": [float("inf")] * 2}
    calls = {"one at a time": lambda: [method.integrate(system, h, steps, x0=x) for x in starts],
             "in one call, 1 thread": lambda: method.integrate_ensemble(system, h, steps, starts, threads=1),
             "in one call, threads": lambda: method.integrate_ensemble(system, h, steps, starts)}
    for _ in range(max(3, rounds // 10)):
        for key, call in calls.items():
            t0, w0 = time.process_time(), time.perf_counter()
            call()
            best[key] = [min(best[key][0], time.process_time() - t0), min(best[key][1], time.perf_counter() - w0)]
    print(f"ensemble of {k} starts, {case} (ms; CPU of the process, all threads, and wall; minimum of rounds); "
          f"the same final states as one at a time: {np.array_equal(one, many)}")
    for key, (cpu, wall) in best.items():
        print(f"  {key:24s} CPU {1e3 * cpu:8.2f}  wall {1e3 * wall:8.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="*", default=CASES, help="SYSTEM/METHOD/H/STEPS")
    parser.add_argument("--rounds", type=int, default=ROUNDS)
    parser.add_argument("--ensemble", type=int, default=ENSEMBLE,
                        help=f"starts of the ensemble ({ENSEMBLE}; 0: none)")
    args = parser.parse_args()
    per_call(args.cases, args.rounds)
    if args.ensemble:
        ensemble(args.cases[0], args.ensemble, args.rounds)


if __name__ == "__main__":
    main()
