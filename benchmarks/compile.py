"""Cold and warm `rkhp converge rigid-body`, the cold start of each class of tapes, and the cost of
a step, before and after a change, in one run.

Run: python benchmarks/compile.py [--before COMMIT] [--also COMMIT] [--rounds N] [--step-runs N]
                                  [--kernels]

Each version is a copy of rkhp (the library, its CLI and its tableau files) in a temporary folder:
the version to compare with from `git archive COMMIT` (default 2575823, the engine before its
state was named: docs/engine.md "The state of the step loop"), this checkout's working tree as
"after". Both run in fresh processes of this Python with PYTHONPATH set to their copy, so that the
same interpreter and numba are measured:

- cold: `python -m rkhp converge rigid-body --format json` with an empty numba cache
  (NUMBA_CACHE_DIR set to a new folder), the whole process: wall and CPU (user + system) seconds;
  and where its compile CPU goes: numba's compile events of each compiled unit (module and
  name), the unit's own CPU seconds (those of the units it compiled on the way left out), the
  units that took at least `UNIT_FLOOR` s printed;
- warm: the same command again, on the cache the cold run filled;
- cold, engine only: `ENGINE_COMMAND`, the command's default methods less RKHP Euler, with an
  empty cache: the whole process's CPU seconds. These three run on the engine's step loop in
  every version; RKHP Euler on the rigid body runs in the closed direct form where it exists
  (`rkhp.integrators.closed_euler`, a loop of its own), so this figure compares the same work
  where the first does not;
- families: `python -m rkhp integrate SYSTEM --method paper-three-stage --steps 10` for one
  system of each class of tapes (`FAMILIES`: the rigid body's plain tapes, the spray tapes of
  charged-particle, the phimv tapes of toda:12), each with an empty cache of its own: the
  whole process's CPU seconds, the interpreter compiled for that class and the loop of explicit
  tableaux linking it;
- us/step: the rigid body at h = 0.05, 1000 steps, with the paper's three-stage method, RKHP
  Euler and the implicit gauss2 (`STEP_METHODS`), warm: CPU seconds of the process around each
  run (the fairer figure on a loaded machine), the minimum over the repeats in a process; the
  versions' step processes alternate (one of each in turn, `--step-runs` turns a round), and the
  minimum and the median over a version's processes are printed, so that neither a burst of
  load nor one process's placement in memory falls on one version only;
- with --kernels, the cold compile of each entry kernel of `rkhp.integrators.kernels`, in the order
  of its table (each figure leaves out what the kernels before it compiled), in one fresh process
  with an empty cache: CPU seconds from numba's compile event of the kernel to its end, the
  figures behind the compile notice's estimates.

Versions alternate within a round, and the minimum over the rounds of the cold and warm runs is
printed, so that a burst of load on a shared machine does not fall on one version only; the load
average is printed too.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BEFORE = "2575823"
COMMAND = ["converge", "rigid-body", "--format", "json"]
ENGINE_COMMAND = ["converge", "rigid-body", "--method", "paper-two-stage", "--method",
                  "paper-three-stage", "--method", "rk4", "--format", "json"]
STEP_METHODS = ("paper-three-stage", "euler", "gauss2")
FAMILIES = ("rigid-body", "charged-particle", "toda:12")
FAMILY_COMMAND = ["integrate", "{system}", "--method", "paper-three-stage", "--steps", "10",
                  "--format", "json"]

STEP_CODE = """
import json, sys, time
from rkhp.integrators import integrate_rkhp
from rkhp.systems import get_system
system, out = get_system("rigid-body"), {}
for method in sys.argv[1:]:
    integrate_rkhp(system, method, 0.05, 2)
    best = float("inf")
    for _ in range(%d):
        start = time.process_time()
        integrate_rkhp(system, method, 0.05, 1000)
        best = min(best, time.process_time() - start)
    out[method] = best / 1000 * 1e6
print(json.dumps(out))
"""


UNIT_FLOOR = 0.3
"""Compiled units of the cold run with less compile CPU than this (s) are left out of its table."""

#: the cold run: the command, with each compiled unit's own compile CPU written to argv[1]
COLD_CODE = """
import atexit, json, runpy, sys, time
from numba.core import event
path, stack, own = sys.argv[1], [], {}
class Units(event.Listener):
    def on_start(self, ev):
        stack.append([time.process_time(), 0.0])
    def on_end(self, ev):
        start, inner = stack.pop()
        spent = time.process_time() - start
        func = ev.data["dispatcher"].py_func
        name = func.__module__ + "." + func.__qualname__
        own[name] = own.get(name, 0.0) + spent - inner
        if stack:
            stack[-1][1] += spent
event.register("numba:compile", Units())
atexit.register(lambda: open(path, "w").write(json.dumps(own)))
sys.argv = ["rkhp", *sys.argv[2:]]
runpy.run_module("rkhp", run_name="__main__", alter_sys=True)
"""


#: the rigid body's first call of each entry kernel, in the order of rkhp.integrators.kernels
KERNEL_CODE = """
import json, time
import numpy as np
from numba.core import event
from rkhp.integrators import rkhp_method
from rkhp.integrators.classical import integrate_classical, integrate_midpoint
from rkhp.integrators.energy import hamiltonian_values
from rkhp.systems import get_system
from rkhp.tableaux.files import load_tableau
KERNELS = ("run_tape", "_hamiltonian_loop", "drive", "_rk_loop", "_midpoint_loop", "_field")
start, out = {}, {}
class Timer(event.Listener):
    def on_start(self, ev):
        name = ev.data["dispatcher"].py_func.__name__
        if name in KERNELS and name not in start:
            start[name] = time.process_time()
    def on_end(self, ev):
        name = ev.data["dispatcher"].py_func.__name__
        if name in start and name not in out:
            out[name] = time.process_time() - start[name]
event.register("numba:compile", Timer())
system, rk4 = get_system("rigid-body"), load_tableau("rk4")
system.hamiltonian(system.x0)
hamiltonian_values(system, np.array([system.x0, system.x0]))
rkhp_method.integrate_rkhp(system, rk4, 0.05, 2)
integrate_classical(system, rk4, 0.05, 2)
integrate_midpoint(system, 0.05, 2)
print(json.dumps(out))
"""


def assemble(dest: Path, commit: str | None) -> Path:
    """A runnable copy of rkhp in `dest`: rkhp/, rkhp_cli/ (from cli/) and rkhp/tables/, from a
    commit or (None) from the working tree."""
    dest.mkdir(parents=True)
    if commit:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "rkhp", "cli", "tables"],
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    else:
        for name in ("rkhp", "cli", "tables"):
            shutil.copytree(ROOT / name, dest / name, ignore=shutil.ignore_patterns("__pycache__"))
    (dest / "cli").rename(dest / "rkhp_cli")
    (dest / "tables").rename(dest / "rkhp" / "tables")
    return dest


def run(tree: Path, args: list[str], cache: Path) -> tuple[float, float, str]:
    """(wall seconds, CPU seconds of the process, stdout) of `python ARGS` on a version."""
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(cache))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, cwd=tree)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{args} failed in {tree}:\n{proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc.stdout


def measure(tree: Path, work: Path) -> dict:
    """Cold and warm converge, and the cold start of each class of tapes, of one version (one
    round); the numba cache that the warm run used is kept for the step timings."""
    cache = Path(tempfile.mkdtemp(prefix="numba-", dir=work))
    units = cache.parent / f"{cache.name}-units.json"
    cold = run(tree, ["-c", COLD_CODE, str(units), *COMMAND], cache)
    warm = run(tree, ["-m", "rkhp", *COMMAND], cache)
    engine_cache = Path(tempfile.mkdtemp(prefix="numba-", dir=work))
    engine = run(tree, ["-m", "rkhp", *ENGINE_COMMAND], engine_cache)[1]
    shutil.rmtree(engine_cache)
    families = {}
    for system in FAMILIES:
        family_cache = Path(tempfile.mkdtemp(prefix="numba-", dir=work))
        command = [part.format(system=system) for part in FAMILY_COMMAND]
        families[system] = run(tree, ["-m", "rkhp", *command], family_cache)[1]
        shutil.rmtree(family_cache)
    return {"cold": cold[:2], "units": json.loads(units.read_text()), "warm": warm[:2],
            "engine": engine, "families": families, "cache": cache}


def step_costs(tree: Path, cache: Path, repeats: int) -> dict:
    """us/step of each of `STEP_METHODS` in one warm process of a version: the minimum over
    `repeats` runs."""
    return json.loads(run(tree, ["-c", STEP_CODE % repeats, *STEP_METHODS], cache)[2])


def _least(rounds: list[dict], kernel: str) -> str:
    """The smallest compile CPU of `kernel` over the rounds, or "-" for a version without it."""
    seconds = [r["kernels"][kernel] for r in rounds if kernel in r["kernels"]]
    return f"{min(seconds):6.2f}" if seconds else f"{'-':>6s}"


def measure_kernels(tree: Path, work: Path) -> dict:
    """CPU seconds of each entry kernel's cold compile (one process, empty cache), one version."""
    cache = Path(tempfile.mkdtemp(prefix="numba-", dir=work))
    seconds = json.loads(run(tree, ["-c", KERNEL_CODE], cache)[2])
    shutil.rmtree(cache)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=BEFORE, help=f"the commit to compare with ({BEFORE})")
    parser.add_argument("--also", action="append", default=[], metavar="COMMIT",
                        help="a further commit to measure (repeatable)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds (minimum taken; default 2)")
    parser.add_argument("--repeats", type=int, default=5, help="runs per step timing (default 5)")
    parser.add_argument("--step-runs", type=int, default=5,
                        help="step processes of each version per round, alternating (default 5)")
    parser.add_argument("--kernels", action="store_true",
                        help="also each entry kernel's cold compile CPU (a process per round)")
    options = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="rkhp-compile-"))
    try:
        versions = {f"before ({options.before})": assemble(work / "before", options.before)}
        for k, commit in enumerate(options.also):
            versions[commit] = assemble(work / f"also{k}", commit)
        versions["after (this tree)"] = assemble(work / "after", None)
        results: dict[str, list[dict]] = {name: [] for name in versions}
        loads = [os.getloadavg()[0]]
        steps: dict[str, list[dict]] = {name: [] for name in versions}
        for _ in range(options.rounds):
            for name, tree in versions.items():
                results[name].append(measure(tree, work))
                if options.kernels:
                    results[name][-1]["kernels"] = measure_kernels(tree, work)
                loads.append(os.getloadavg()[0])
            for _ in range(options.step_runs):  # one process of each version in turn
                for name, tree in versions.items():
                    steps[name].append(step_costs(tree, results[name][-1]["cache"], options.repeats))
            loads.append(os.getloadavg()[0])
        print(f"machine: {os.cpu_count()} CPUs, load average {min(loads):.1f} to {max(loads):.1f} "
              f"during the runs; `rkhp {' '.join(COMMAND)}`, minima over {options.rounds} rounds")
        print(f"{'version':24s} {'cold wall':>10s} {'cold CPU':>9s} {'warm wall':>10s} {'warm CPU':>9s} "
              f"{'engine only, cold CPU':>22s}")
        for name, rounds in results.items():
            cold = [min(r["cold"][k] for r in rounds) for k in (0, 1)]
            warm = [min(r["warm"][k] for r in rounds) for k in (0, 1)]
            engine = min(r["engine"] for r in rounds)
            print(f"{name:24s} {cold[0]:9.1f}s {cold[1]:8.1f}s {warm[0]:9.2f}s {warm[1]:8.2f}s "
                  f"{engine:21.1f}s")
        print(f"engine only: `rkhp {' '.join(ENGINE_COMMAND)}`")
        print(f"compile CPU of the cold run by compiled unit (s, its own, the round of the least "
              f"cold CPU; units under {UNIT_FLOOR} s left out)")
        for name, rounds in results.items():
            units = min(rounds, key=lambda r: r["cold"][1])["units"]
            print(f"{name:24s} total {sum(units.values()):5.1f}s: " + ", ".join(
                f"{unit} {seconds:.1f}" for unit, seconds in sorted(units.items(), key=lambda u: -u[1])
                if seconds >= UNIT_FLOOR))
        processes = options.rounds * options.step_runs
        print(f"us/step, minimum and median over {processes} processes per version (the versions' "
              f"processes alternating), each the minimum of {options.repeats} runs of 1000 steps")
        print(f"{'version':24s} " + " ".join(f"{m:>21s}" for m in STEP_METHODS))
        for name, runs in steps.items():
            print(f"{name:24s} " + " ".join(
                f"{min(r[m] for r in runs):10.2f}{statistics.median(r[m] for r in runs):11.2f}"
                for m in STEP_METHODS))
        print(f"cold start CPU (s, minima) of `rkhp {' '.join(FAMILY_COMMAND)}` per class of tapes")
        print(f"{'version':24s} " + " ".join(f"{system:>16s}" for system in FAMILIES))
        for name, rounds in results.items():
            print(f"{name:24s} " + " ".join(f"{min(r['families'][f] for r in rounds):15.1f}s"
                                            for f in FAMILIES))
        if options.kernels:
            names = list(results["after (this tree)"][0]["kernels"])
            print("cold compile CPU of each entry kernel (s, minima): " + ", ".join(names))
            for name, rounds in results.items():
                print(f"{name:24s} " + " ".join(_least(rounds, k) for k in names))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
