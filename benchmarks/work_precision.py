"""Work-precision race: rkhp's compositions and paper-three-stage against scipy's DOP853 and Radau
(docs/compositions.md "Work-precision"). Run: python benchmarks/work_precision.py [--quick]

For each system and each target end-point error (1e-6, 1e-8, 1e-10, 1e-12 at T = 10, 2-norm against
the reference of rkhp.studies.reference), every method gets its cheapest setting reaching the target:
the fewest steps among 2^k (rkhp) or the loosest rtol among 10^(-k/2) (scipy, atol = 1e-3 rtol). The
settings are then timed together, interleaved (one call of each per round) and warm (compiled, numba
cache loaded), and the minimum wall time over the rounds is reported.

The peers run scipy.integrate.solve_ivp on the system's vector field x -> pi(x) grad H(x) compiled with
numba (rkhp.integrators.classical.vector_field): a right-hand side faster than the plain numpy one
a user writes, so the ratio is not flattered.

Part 2 (T = 10^4): energy and Casimir errors of kahan-li8 against DOP853 when both take the same
time (DOP853 at the rtol whose time is nearest to kahan-li8's).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rkhp.integrators.classical import vector_field
from rkhp.integrators.methods import resolve_method, resolve_system
from rkhp.studies.reference import reference

SYSTEMS = ("rigid-body", "lotka-volterra", "charged-particle", "nambu", "toda:12")
METHODS = ("paper-three-stage", "suzuki4", "kahan-li6", "kahan-li8", "sofroniou-spaletta10")
PEERS = ("DOP853", "Radau")
TARGETS = (1e-6, 1e-8, 1e-10, 1e-12)
T_FINAL = 10.0
ROUNDS = 5
STEPS = tuple(2**k for k in range(2, 16))
TOLERANCES = tuple(10.0 ** (-k / 2) for k in range(6, 29))


def solve(f, solver, x0, t_final, rtol):
    from scipy.integrate import solve_ivp

    return solve_ivp(lambda t, x: f(x), (0.0, t_final), x0, method=solver, rtol=rtol, atol=1e-3 * rtol)


def rkhp_runner(method, system, n):
    return lambda: method.integrate(system, T_FINAL / n, n).final_state


def scipy_runner(f, solver, x0, rtol):
    return lambda: solve(f, solver, x0, T_FINAL, rtol).y[:, -1]


def cheapest_rkhp(method, system, ref, targets):
    """target -> (steps, error) of the fewest steps 2^k reaching it (None if none up to 2^15)."""
    out, pending = {}, list(targets)
    for n in STEPS:
        if not pending:
            break
        traj = method.integrate(system, T_FINAL / n, n)
        if not traj.ok:
            continue
        err = float(np.linalg.norm(traj.final_state - ref.state))
        for t in [t for t in pending if err <= t]:
            out[t] = (n, err)
            pending.remove(t)
    return out


def cheapest_scipy(f, solver, x0, ref, targets):
    out, pending = {}, list(targets)
    for rtol in TOLERANCES:
        if not pending:
            break
        sol = solve(f, solver, x0, T_FINAL, rtol)
        if not sol.success:
            continue
        err = float(np.linalg.norm(sol.y[:, -1] - ref.state))
        for t in [t for t in pending if err <= t]:
            out[t] = (rtol, err)
            pending.remove(t)
    return out


def interleaved(runners: dict) -> dict:
    """name -> minimum wall seconds over ROUNDS rounds, each round calling every runner once."""
    best = {k: np.inf for k in runners}
    for run in runners.values():
        run()  # warm
    for _ in range(ROUNDS):
        for name, run in runners.items():
            t0 = time.perf_counter()
            run()
            best[name] = min(best[name], time.perf_counter() - t0)
    return best


def _ms(seconds) -> str:
    return "-" if seconds is None else f"{seconds * 1e3:.3f} ms"


def race_line(system_name: str, target: float, ours: dict, times: dict, settings: dict) -> str:
    """One row: the best rkhp method and its time, DOP853's and Radau's, the ratio, every method."""
    best = min(ours, key=ours.get) if ours else None
    dop = times.get("DOP853")
    ratio = f"{dop / ours[best]:.2f}x" if best and dop else "-"
    setting = settings["DOP853"].get(target)
    rtol = "-" if setting is None else f"{setting[0]:.3g}"
    detail = ", ".join(f"{m} {settings[m][target][0]} steps {_ms(t)}" for m, t in ours.items())
    return (f"{system_name:17s} {target:7.0e}  best {best or '-':21s} {_ms(ours.get(best)):>11s}  "
            f"DOP853 {_ms(dop):>11s} (rtol {rtol})  Radau {_ms(times.get('Radau')):>11s}  "
            f"DOP853/rkhp {ratio}   [{detail}]")


def race(system_name: str, methods, targets) -> list[str]:
    system = resolve_system(system_name)
    ref = reference(system, T_FINAL)
    f = vector_field(system)
    x0 = np.asarray(system.x0, dtype=float)
    settings = {m: cheapest_rkhp(resolve_method(m), system, ref, targets) for m in methods}
    settings.update({p: cheapest_scipy(f, p, x0, ref, targets) for p in PEERS})
    lines = []
    for target in targets:
        runners = {}
        for m in methods:
            if target in settings[m]:
                runners[m] = rkhp_runner(resolve_method(m), system, settings[m][target][0])
        for p in PEERS:
            if target in settings[p]:
                runners[p] = scipy_runner(f, p, x0, settings[p][target][0])
        times = interleaved(runners)
        lines.append(race_line(system_name, target, {m: times[m] for m in methods if m in times},
                               times, settings))
        print(lines[-1], flush=True)
    return lines


def long_run(system_name: str = "nambu", method: str = "kahan-li8", t_final: float = 1e4, h: float = 0.1):
    """Energy and Casimir errors over T = 10^4 of `method` and of DOP853 at about the same time."""
    system = resolve_system(system_name)
    n = int(round(t_final / h))
    t0 = time.perf_counter()
    traj = resolve_method(method).integrate(system, h, n).raise_if_failed()
    ours = time.perf_counter() - t0
    f = vector_field(system)
    x0 = np.asarray(system.x0, dtype=float)

    def drift(states):
        e0, c0 = system.hamiltonian(states[0]), system.casimir_values(states[0])
        energy = max(abs(system.hamiltonian(x) - e0) for x in states)
        casimir = max(float(np.abs(system.casimir_values(x) - c0).max()) for x in states) if len(c0) else 0.0
        return energy, casimir

    e, c = drift(traj.states[:: max(1, n // 2000)])
    print(f"{system_name} T = {t_final:g}: {method} h = {h} {ours:.2f} s: energy error {e:.2e}, Casimir error {c:.2e}")
    from scipy.integrate import solve_ivp

    for rtol in (1e-6, 1e-8, 1e-10, 1e-12):
        t0 = time.perf_counter()
        sol = solve_ivp(lambda t, x: f(x), (0.0, t_final), x0, method="DOP853", rtol=rtol, atol=1e-3 * rtol)
        spent = time.perf_counter() - t0
        e, c = drift(sol.y.T[:: max(1, sol.y.shape[1] // 2000)])
        print(f"{'':{len(system_name)}s}              DOP853 rtol {rtol:g} {spent:.2f} s: energy error {e:.2e}, "
              f"Casimir error {c:.2e}")


def main(argv) -> None:
    quick = "--quick" in argv
    systems = SYSTEMS[:1] if quick else SYSTEMS
    print(f"# python {' '.join(['benchmarks/work_precision.py', *argv])}  ({time.strftime('%Y-%m-%d %H:%M')})")
    print(f"# T = {T_FINAL:g}; cheapest setting per target; min of {ROUNDS} interleaved warm rounds")
    for name in systems:
        race(name, METHODS, TARGETS)
    if not quick:
        long_run()


if __name__ == "__main__":
    main(sys.argv[1:])
