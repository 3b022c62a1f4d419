"""Targets of issue 5 for the RKHP engine (prints measured figures; run: python benchmarks/integrate.py).

1. Rigid body, the paper's 3-stage method: us/step of one trajectory (target <= 10) and the
   compile time in a fresh process (target <= 3 s with numba's cache warm).
2. A 6-stage tableau (butcher5) per step against the 3-stage one (target <= 10x).
3. 10^4 trajectories at once (integrate_ensemble, threads over the compiled loop).
4. Wall time at equal final error 1e-8 (T = 10) against scipy's solve_ivp(DOP853).

Wall and CPU (process) seconds are both printed: on a loaded machine the CPU time is the fairer
figure for a single thread.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np

from rkhp.integrators import integrate_ensemble, integrate_rkhp
from rkhp.systems import get_system

REPEATS = 5


def timed(fn):
    """(min wall seconds, min CPU seconds) over REPEATS calls."""
    walls, cpus = [], []
    for _ in range(REPEATS):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return min(walls), min(cpus)


def per_step(system, method, h, steps):
    """(us/step wall, us/step CPU, mean Newton iterations), minima over REPEATS runs."""
    integrate_rkhp(system, method, h, 2)
    runs, cpus = [], []
    for _ in range(REPEATS):
        c = time.process_time()
        runs.append(integrate_rkhp(system, method, h, steps))
        cpus.append(time.process_time() - c)
    assert all(r.ok for r in runs)
    return (min(r.run_seconds for r in runs) / steps * 1e6, min(cpus) / steps * 1e6,
            float(np.mean(runs[0].newton_iterations)))


def fresh_compile_seconds() -> float:
    code = ("from rkhp.systems import get_system; from rkhp.integrators import integrate_rkhp; "
            "print(integrate_rkhp(get_system('rigid-body'), 'paper-three-stage', 0.1, 1)"
            ".compile_seconds)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def main() -> None:
    rb = get_system("rigid-body")
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    integrate_rkhp(rb, "paper-three-stage", 0.1, 1)  # fill the cache
    print(f"[1] compile (fresh process, cache warm): {fresh_compile_seconds():.2f} s "
          "(target <= 3 s)")
    for h, steps in ((0.1, 1000), (0.01, 1000)):
        us, cpu, newton = per_step(rb, "paper-three-stage", h, steps)
        print(f"[1] rigid body, paper-three-stage, h = {h}: {us:.2f} us/step wall, {cpu:.2f} "
              f"us/step CPU (Newton {newton:.2f}/step; target <= 10 us)")
    _, cpu3, _ = per_step(rb, "paper-three-stage", 0.05, 1000)
    for method, stages in (("rk4", 4), ("butcher5", 6)):
        us, cpu, newton = per_step(rb, method, 0.05, 1000)
        print(f"[2] {method} ({stages} stages), h = 0.05: {cpu:.2f} us/step CPU = "
              f"{cpu / cpu3:.2f} x the 3-stage ({cpu3:.2f} us/step CPU)"
              f"{' (target <= 10x)' if stages == 6 else ''}")

    rng = np.random.default_rng(0)
    x0s = rng.normal(size=(10_000, 3))
    x0s /= np.linalg.norm(x0s, axis=1)[:, None]
    integrate_ensemble(rb, "paper-three-stage", 0.1, 2, x0s[:4])
    steps = 20
    w, c = time.perf_counter(), time.process_time()
    integrate_ensemble(rb, "paper-three-stage", 0.1, steps, x0s)
    wall, cpu = time.perf_counter() - w, time.process_time() - c
    print(f"[3] 10^4 trajectories x {steps} steps (h = 0.1): wall {wall:.2f} s, CPU {cpu:.2f} s, "
          f"{wall / (1e4 * steps) * 1e6:.2f} us/step wall with {len(os.sched_getaffinity(0))} "
          "threads")

    work_precision(rb)


def work_precision(rb) -> None:
    from scipy.integrate import solve_ivp

    T, target = 10.0, 1e-8
    exact = rb.exact_solution(T)
    for n in range(100, 400, 5):
        tr = integrate_rkhp(rb, "paper-three-stage", T / n, n)
        err = float(np.abs(tr.final_state - exact).max())
        if err <= target:
            break
    wall, cpu = timed(lambda: integrate_rkhp(rb, "paper-three-stage", T / n, n))
    print(f"[4] RKHP paper-three-stage: {n} steps, error {err:.2e}: wall {wall * 1e3:.2f} ms, "
          f"CPU {cpu * 1e3:.2f} ms (including the Python call)")
    inertia = np.array([2.0, 1.0, 2.0 / 3.0])

    def f(t, x):
        return np.cross(x, x / inertia)

    for rtol in 10.0 ** -np.arange(6, 14, 0.5):
        sol = solve_ivp(f, (0, T), rb.x0, method="DOP853", rtol=rtol, atol=rtol)
        err = float(np.abs(sol.y[:, -1] - exact).max())
        if err <= target:
            break
    wall, cpu = timed(lambda: solve_ivp(f, (0, T), rb.x0, method="DOP853", rtol=rtol, atol=rtol))
    print(f"[4] scipy DOP853 rtol = atol = {rtol:.1e}: {sol.nfev} evaluations, error {err:.2e}: "
          f"wall {wall * 1e3:.2f} ms, CPU {cpu * 1e3:.2f} ms")


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/integrate.py", __doc__).parse_args()
    main()
