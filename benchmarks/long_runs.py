"""Long runs against the compiled DOP853 at equal CPU time (docs/compositions.md "Long runs"; the
generated page docs/results/long-runs.md).

Run: python benchmarks/long_runs.py [SYSTEM ...] [--t-final T] [--write PAGE]

SYSTEM: built-in names or spec files (default: nambu, charged-particle, rigid-body); T defaults to
10^5. For each system, from its start over [0, T]:

- the compiled DOP853 (numbalsoda's, on a numba cfunc field; scipy's where it is not installed) at
  rtol 1e-8 ... 1e-15 (atol 1e-3 rtol): CPU seconds of the calling thread for one solve (warm), and
  the largest energy and Casimir errors at SAMPLES + 1 equally spaced times;
- rkhp's methods of LADDER at their step sizes: CPU seconds of the calling thread for one run
  (warm: the loop compiled by a short run before), and the largest errors at the same times (every
  step size divides T / SAMPLES, so the same states are compared); a run whose Newton iterations
  fail is reported as failed.

At equal CPU time: for each rkhp run, the DOP853 run with the smallest errors among those that
took at most its CPU time (DOP853's best within that time; a tighter rtol than 1e-15 gains nothing,
round-off then grows), and the ratios of that run's errors to rkhp's (above 1: rkhp's are smaller).
No DOP853 run that cheap: "-". Errors are absolute (energy: |H(x(t)) - H(x0)|; Casimir: the
largest |C_k(x(t)) - C_k(x0)|).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from rkhp.integrators.methods import resolve_method, resolve_system
from rkhp.studies import peers as P

sys.path.insert(0, str(Path(__file__).resolve().parent))
from work_precision import machine, parser, peer_of, run_script, versions  # noqa: E402

SYSTEMS = ("nambu", "charged-particle", "rigid-body")
T_FINAL = 1e5
SAMPLES = 2000
RTOLS = (1e-8, 1e-10, 1e-12, 1e-14, 1e-15)
LADDER = {"euler": (0.5, 0.25), "suzuki4": (0.5,), "kahan-li8": (0.5, 0.25, 0.1)}
"""rkhp's methods and their step sizes (each divides T / SAMPLES for T = 10^k, k >= 3; at h = 1
on nambu every one of them fails in its first steps, at T = 10^3). kahan-li8's smallest step
brings its energy error below what DOP853 reaches at any tolerance, where round-off is not yet
its limit (10^6 steps of 17 substeps)."""


class Run(NamedTuple):
    """One long run: its setting, CPU seconds, largest energy and Casimir errors (NaN: none, as
    for a system without Casimirs), and what failed (empty when it reached T)."""

    label: str
    cpu: float
    energy: float
    casimir: float
    failure: str


def errors(system, states: np.ndarray) -> tuple[float, float]:
    """The largest energy and Casimir errors over `states` against the first."""
    e0, c0 = system.hamiltonian(states[0]), np.asarray(system.casimir_values(states[0]))
    energy = max(abs(system.hamiltonian(x) - e0) for x in states)
    casimir = (max(float(np.abs(np.asarray(system.casimir_values(x)) - c0).max()) for x in states)
               if c0.size else math.nan)
    return float(energy), casimir


def dop853_runs(system, t_final: float, name: str) -> list[Run]:
    """The DOP853 peer `name` over the rtols of RTOLS (compiled and warmed up first)."""
    prepared = P.prepare(peer_of(name), system, t_final, samples=SAMPLES)
    x0 = np.asarray(system.x0, dtype=float)
    runs = []
    for rtol in RTOLS:
        prepared.solve(x0, rtol)  # warm at this tolerance
        cpu = time.thread_time()
        sol = prepared.solve(x0, rtol)
        spent = time.thread_time() - cpu
        runs.append(Run(f"{name}, rtol {rtol:g}", spent, *errors(system, sol.states),
                        "" if sol.ok else sol.message))
        print(line(runs[-1]), flush=True)
    return runs


def rkhp_runs(system, t_final: float) -> list[Run]:
    """The methods of LADDER at their step sizes over [0, t_final]."""
    runs = []
    for name, steps in LADDER.items():
        method = resolve_method(name)
        for h in steps:
            n = int(round(t_final / h))
            every = int(round(t_final / SAMPLES / h))
            method.integrate(system, h, 10)  # compiles or loads the loop, prepares the data
            cpu = time.thread_time()
            traj = method.integrate(system, h, n)
            spent = time.thread_time() - cpu
            label = f"{name}, h = {h:g}"
            if not traj.ok:
                runs.append(Run(label, spent, math.nan, math.nan, traj.status))
            else:
                runs.append(Run(label, spent, *errors(system, traj.states[::every]), ""))
            print(line(runs[-1]), flush=True)
    return runs


def best_within(peer: list[Run], cpu: float) -> Run | None:
    """The peer's run with the smallest largest error among those of at most `cpu` seconds."""
    fit = [r for r in peer if r.cpu <= cpu and not r.failure]
    return min(fit, key=lambda r: max(r.energy, 0.0 if math.isnan(r.casimir) else r.casimir)) if fit else None


def _e(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.1e}"


def _ratio(theirs: float, ours: float) -> str:
    if math.isnan(theirs) or math.isnan(ours):
        return "-"
    return f"{theirs / ours:.3g}" if ours > 0 else "inf"


def line(run: Run) -> str:
    return f"| {run.label} | {run.cpu:.3g} | {_e(run.energy)} | {_e(run.casimir)} | {run.failure or 'ok'} |"


def comparison(ours: list[Run], peer: list[Run]) -> list[str]:
    """Rows: each rkhp run against DOP853's best within its CPU time."""
    rows = []
    for run in ours:
        if run.failure:
            rows.append(f"| {run.label} | {run.cpu:.3g} | failed | | | | |")
            continue
        best = best_within(peer, run.cpu)
        if best is None:
            rows.append(f"| {run.label} | {run.cpu:.3g} | - | | | | |")
            continue
        rows.append(f"| {run.label} | {run.cpu:.3g} | {best.label} ({best.cpu:.3g} s) | {_e(best.energy)} | "
                    f"{_e(best.casimir)} | {_ratio(best.energy, run.energy)} | {_ratio(best.casimir, run.casimir)} |")
    return rows


RUN_HEAD = ["| setting | CPU s | energy error | Casimir error | status |", "|---|---|---|---|---|"]
COMPARE_HEAD = ["| rkhp setting | CPU s | DOP853's best within that CPU time | its energy error | its Casimir error "
                "| energy: DOP853 / rkhp | Casimir: DOP853 / rkhp |", "|---|---|---|---|---|---|---|"]


def study(name: str, t_final: float, peer_name: str) -> list[str]:
    """The markdown section of one system."""
    system = resolve_system(name)
    print(f"# {system.name} (n = {system.dim}, {system.family}), T = {t_final:g}", flush=True)
    peer = dop853_runs(system, t_final, peer_name)
    ours = rkhp_runs(system, t_final)
    return [f"## `{system.name}`, T = {t_final:g}", "", *RUN_HEAD, *map(line, peer + ours), "",
            "At equal CPU time:", "", *COMPARE_HEAD, *comparison(ours, peer), ""]


def positive(text: str) -> float:
    """--t-final: a positive finite number."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"not a positive number: {text!r}")
    return value


def main(argv) -> None:
    argv = list(argv)
    command = " ".join(["python benchmarks/long_runs.py", *argv])
    p = parser("python benchmarks/long_runs.py", __doc__)
    p.add_argument("systems", nargs="*", metavar="SYSTEM", help="built-in names or spec files")
    p.add_argument("--t-final", type=positive, default=T_FINAL, metavar="T", help="the end time")
    p.add_argument("--write", metavar="PAGE", help="write the page here")
    args = p.parse_args(argv)
    t_final, write, systems = args.t_final, args.write, tuple(args.systems) or SYSTEMS
    started, where = time.strftime("%Y-%m-%d %H:%M"), machine()
    print(f"# {command}  ({started}; {where})", flush=True)
    peer_name = "scipy:dop853" if P.absent(peer_of("numbalsoda:dop853")) else "numbalsoda:dop853"
    sections = []
    for name in systems:
        sections += study(name, t_final, peer_name)
    if write:
        text = ["# Long runs against the compiled DOP853 (generated)", "",
                "Generated by `benchmarks/long_runs.py`; do not edit by hand: run it again.", "",
                f"- command: `{command}`", f"- date: {started}", f"- machine: {where}",
                f"- packages: {versions()}",
                f"- errors: the largest over {SAMPLES + 1} equally spaced times from 0 to T, absolute; CPU time of "
                "the calling thread for one run, warm (compiled before).",
                f"- DOP853: {peer_name}, atol = 1e-3 rtol. At equal CPU time, each rkhp run is set against "
                "DOP853's run with the smallest errors among those that took at most its CPU time.", "", *sections]
        Path(write).write_text("\n".join(text))
        print(f"# written: {write}")


if __name__ == "__main__":
    run_script(main, sys.argv[1:])
