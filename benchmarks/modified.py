"""Cost and effect of the modified Hamiltonian (issue 14). Run: `.venv/bin/python benchmarks/modified.py`.

1. `rkhp modified` as a whole process (wall and CPU seconds of the child, best of 3), on T_0 to
   orders 6 and 8, for the paper's three-stage method (weights in Q(sqrt 3)) and RKHP Euler; the
   peer measured in the same run is `rkhp conditions --order 6 --degenerate`, the process start-up.
   Targets (issue 14): order 6 in <= 2 s, order 8 in <= 30 s.
2. The rigid body, paper-three-stage, h = 0.2, 10^4 steps (symmetric realisation): the maximum over
   the run of |H~_N(y_n) - H~_N(y_0)| for N = 4, 6, 8 against the same for H, and the cost of one
   evaluation of H~_N.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import time

RKHP = [sys.executable, "-m", "rkhp"]


def process_seconds(args: list[str], repeat: int = 3) -> tuple[float, float]:
    """(wall, CPU) seconds of the child process, the best of ``repeat`` runs."""
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(RKHP + args, check=True, capture_output=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
        best = min(best, (wall, cpu))
    return best


def commands() -> None:
    print("command                                                        wall [s]  CPU [s]")
    runs = [["conditions", "--order", "6", "--degenerate"]]
    runs += [["modified", "--method", method, "--order", order, cls]
             for method, order in (("paper-three-stage", "6"), ("euler", "6"), ("paper-three-stage", "8"))
             for cls in ("--symmetric", "--degenerate")]
    for args in runs:
        code = subprocess.run(RKHP + args, capture_output=True).returncode
        wall, cpu = process_seconds(args, 1 if "8" in args else 3)
        note = "" if code == 0 else f"  (exit {code})"
        print(f"rkhp {' '.join(args):57s} {wall:8.2f}  {cpu:7.2f}{note}")


def rigid_body() -> None:
    from rkhp.integrators import integrate_rkhp
    from rkhp.integrators.modified_energy import ModifiedEnergy, energy_errors
    from rkhp.series.modified import method_character, modified_hamiltonian
    from rkhp.systems import get_system
    from rkhp.tableaux.files import load_tableau

    system = get_system("rigid-body")
    tableau = load_tableau("paper-three-stage")
    h, steps = 0.2, 10_000
    states = integrate_rkhp(system, tableau, h, steps).states
    print(f"\nrigid body, paper-three-stage, h = {h}, {steps} steps, symmetric realisation")
    print("  N   max|H~_N - H~_N(y0)|   max|H - H(y0)|   ratio   per state [ms]")
    a = method_character(tableau, 8)
    for N in (4, 6, 8):
        series = modified_hamiltonian(a, N, "symmetric")
        t0 = time.perf_counter()
        report = energy_errors(system, series, h, states)
        per_state = (time.perf_counter() - t0) / len(states) * 1e3
        ratio = report["energy_error_max"] / report["modified_energy_error"]
        print(f"  {N}   {report['modified_energy_error']:20.3e}   {report['energy_error_max']:14.3e}   "
              f"{ratio:5.0f}   {per_state:14.2f}")
    one = ModifiedEnergy(system, modified_hamiltonian(a, 8, "symmetric"), h)
    t0 = time.perf_counter()
    for x in states[:200]:
        one(x)
    print(f"  H~_8 alone: {(time.perf_counter() - t0) / 200 * 1e3:.2f} ms per state; "
          f"H: {_hamiltonian_us(system, states[:2000]):.1f} us per state")


def _hamiltonian_us(system, states) -> float:
    t0 = time.perf_counter()
    for x in states:
        system.hamiltonian(x)
    return (time.perf_counter() - t0) / len(states) * 1e6


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/modified.py", __doc__).parse_args()
    commands()
    rigid_body()
