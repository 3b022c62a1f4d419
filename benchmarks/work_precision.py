"""Work-precision race: rkhp's compositions against compiled and plain peers (docs/compositions.md
"Work-precision"; the generated page docs/results/work-precision.md).

Run: python benchmarks/work_precision.py [SYSTEM ...] [--quick] [--targets 1e-8,1e-10,1e-12]
     [--rounds N] [--processes K] [--write PAGE]

SYSTEM: built-in names or spec files (default: rigid-body, lotka-volterra, charged-particle, nambu,
toda:12 and benchmarks/data/vortices-8.toml, 8 variables with a general pi). For each system and
each target end-point error at T = 10 (2-norm against the best reference rkhp has,
rkhp.studies.peers.best_reference: the closed form, or the tighter of scipy's DOP853 and the
compiled DOP853 at rtol 1e-15 cross-checked at 1e-14), every contender gets its cheapest setting
reaching the target: the fewest steps on a grid of ratio 2^(1/4) (rkhp), the loosest rtol on a grid
of ratio 10^(1/4) (peers, atol = 1e-3 rtol). The settings are then timed together: warm (compiled,
traced, numba cache loaded; compile times are left out), interleaved (each round calls every
contender, in an order rotated by one each round; a call shorter than BATCH_SECONDS is repeated
within its timing and the mean taken), ROUNDS rounds; the minimum over the rounds of the CPU time
of the calling thread (time.thread_time) is reported, and of the wall time beside it. With
--processes K the race runs in K fresh processes one after another and each time is the minimum
over them: a contender's time varies from one process to the next (up to 1.5x for the peers at
the same settings), beyond what rounds within one process see.

Contenders (rkhp.studies.peers; every field is generated from the system, so spec files race too):
- rkhp: the compositions of METHODS, the best of them per target (the processed compositions
  bcm6-s11, bcm6-s13 and bcm8-s13 among them, their inverse processor applied once, at the end:
  every rkhp run keeps its last state only);
- numbalsoda:dop853: Hairer's DOP853 (Fortran) on a numba cfunc field, the whole loop compiled;
- diffrax:dopri8, diffrax:tsit5: under jax.jit on the CPU, float64;
- scipy:dop853: solve_ivp on the field a user writes with plain arithmetic.
A compiled peer whose package is not installed is printed as absent (pip install 'rkhp[peers]').

Long runs (T = 10^5, at equal CPU time) are benchmarks/long_runs.py.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from rkhp.integrators.methods import resolve_method, resolve_system
from rkhp.studies import peers as P

ROOT = Path(__file__).resolve().parent.parent
SYSTEMS = ("rigid-body", "lotka-volterra", "charged-particle", "nambu", "toda:12",
           str(Path("benchmarks") / "data" / "vortices-8.toml"))
METHODS = ("suzuki4", "kahan-li6", "kahan-li8", "sofroniou-spaletta10", "bcm6-s11", "bcm6-s13", "bcm8-s13")
PEERS = ("numbalsoda:dop853", "diffrax:dopri8", "diffrax:tsit5", "scipy:dop853")
TARGETS = (1e-8, 1e-10, 1e-12)
T_FINAL = 10.0
ROUNDS = 7
BATCH_SECONDS = 2e-3
STEPS = tuple(sorted({int(round(2 ** (k / 4))) for k in range(8, 4 * 16 + 1)}))
TOLERANCES = tuple(10.0 ** (-k / 4) for k in range(12, 61))


def peer_of(name: str) -> P.Peer:
    return P.scipy_peer("DOP853") if name == "scipy:dop853" else P.COMPILED_PEERS[name]


def cheapest_steps(method, system, ref, targets) -> dict:
    """target -> (steps, error) of the fewest steps of STEPS reaching it (none: left out)."""
    out, pending = {}, sorted(targets, reverse=True)
    for n in STEPS:
        if not pending:
            break
        traj = method.integrate(system, T_FINAL / n, n, keep_all=False)
        if not traj.ok:
            continue
        err = float(np.linalg.norm(traj.final_state - ref.state))
        while pending and err <= pending[0]:
            out[pending.pop(0)] = (n, err)
    return out


def cheapest_tolerance(prepared, x0, ref, targets) -> dict:
    """target -> (rtol, error) of the loosest rtol of TOLERANCES reaching it."""
    out, pending = {}, sorted(targets, reverse=True)
    for rtol in TOLERANCES:
        if not pending:
            break
        sol = prepared.solve(x0, rtol)
        if not sol.ok:
            continue
        err = float(np.linalg.norm(sol.state - ref.state))
        while pending and err <= pending[0]:
            out[pending.pop(0)] = (rtol, err)
    return out


def batch_of(call) -> int:
    """Calls per timing: enough to last BATCH_SECONDS of CPU time."""
    start = time.thread_time()
    call()
    return max(1, math.ceil(BATCH_SECONDS / max(time.thread_time() - start, 1e-7)))


def interleaved(runners: dict, rounds: int) -> dict:
    """name -> (minimum CPU seconds of the calling thread, minimum wall seconds) per call."""
    batches = {k: batch_of(run) for k, run in runners.items()}
    best = {k: [math.inf, math.inf] for k in runners}
    names = list(runners)
    for r in range(rounds):
        for name in names[r % len(names):] + names[:r % len(names)]:
            run, k = runners[name], batches[name]
            wall, cpu = time.perf_counter(), time.thread_time()
            for _ in range(k):
                run()
            cpu, wall = (time.thread_time() - cpu) / k, (time.perf_counter() - wall) / k
            best[name] = [min(best[name][0], cpu), min(best[name][1], wall)]
    return {k: tuple(v) for k, v in best.items()}


class Row:
    """One system at one target: the settings and times of every contender."""

    def __init__(self, system: str, target: float):
        self.system, self.target = system, target
        self.cells: dict[str, tuple] = {}  # name -> (setting text, cpu s, wall s, error)


def row_records(rows: list[Row]) -> list[dict]:
    """The rows as JSON records (what a process of --processes hands back)."""
    return [{"system": r.system, "target": r.target, "cells": {k: list(v) for k, v in r.cells.items()}}
            for r in rows]


def fastest(runs: list[list[dict]]) -> list[Row]:
    """The rows of several processes' runs of the same race (`row_records`), each time the minimum
    over the runs (CPU and wall apart); the settings and errors are the runs' own, the same in
    each (the search is deterministic: a run that found another is refused)."""
    rows = []
    for records in zip(*runs, strict=True):
        first = records[0]
        row = Row(first["system"], first["target"])
        for name, cell in first["cells"].items():
            setting, err = cell[0], cell[3]
            for other in records[1:]:
                if other["cells"][name][0] != setting:
                    raise RuntimeError(f"{row.system} at {row.target:.0e}: {name} found another setting "
                                       f"in another process ({other['cells'][name][0]} against {setting})")
            row.cells[name] = (setting, min(r["cells"][name][1] for r in records),
                               min(r["cells"][name][2] for r in records), err)
        rows.append(row)
    return rows


def in_processes(argv: list[str], processes: int) -> list[Row]:
    """The race of `argv` run in `processes` fresh processes, one after another (`fastest`)."""
    import subprocess
    import tempfile

    runs = []
    with tempfile.TemporaryDirectory() as folder:
        for k in range(processes):
            out = Path(folder) / f"rows-{k}.json"
            print(f"# process {k + 1} of {processes}", flush=True)
            subprocess.run([sys.executable, __file__, *argv, "--rows-json", str(out)], check=True)
            runs.append(json.loads(out.read_text()))
    return fastest(runs)


def race(name: str, targets, rounds: int, absent: dict) -> list[Row]:
    system = resolve_system(name)
    ref = P.best_reference(system, T_FINAL)
    x0 = np.asarray(system.x0, dtype=float)
    print(f"# {system.name} (n = {system.dim}, {system.family}): reference {ref.kind}, estimated error "
          f"{ref.error_estimate:.1e}", flush=True)
    methods = {m: resolve_method(m) for m in METHODS}
    settings = {m: cheapest_steps(method, system, ref, targets) for m, method in methods.items()}
    prepared = {p: P.prepare(peer_of(p), system, T_FINAL) for p in PEERS if p not in absent}
    settings.update({p: cheapest_tolerance(prep, x0, ref, targets) for p, prep in prepared.items()})
    rows = []
    for target in targets:
        runners = {}
        for m, method in methods.items():
            if target in settings[m]:
                n = settings[m][target][0]
                runners[m] = lambda method=method, n=n: method.integrate(system, T_FINAL / n, n, keep_all=False)
        for p, prep in prepared.items():
            if target in settings[p]:
                runners[p] = lambda prep=prep, rtol=settings[p][target][0]: prep.solve(x0, rtol)
        times = interleaved(runners, rounds)
        row = Row(system.name, target)
        for key, (cpu, wall) in times.items():
            setting, err = settings[key][target]
            text = f"{setting} steps" if key in methods else f"rtol {setting:.2g}"
            row.cells[key] = (text, cpu, wall, err)
        rows.append(row)
        print(line(row, absent), flush=True)
    return rows


def processed(method: str) -> bool:
    """Whether a method of METHODS is a processed composition."""
    return resolve_method(method).composition.processed


def best_rkhp(row: Row, among=None):
    """The rkhp method of the row with the least CPU time (among those of `among`, default
    METHODS)."""
    ours = [m for m in (METHODS if among is None else among) if m in row.cells]
    return min(ours, key=lambda m: row.cells[m][1]) if ours else None


def gain(row: Row) -> str:
    """The best plain composition's CPU time over the best processed one's (> 1: processing
    wins), with their names."""
    plain = best_rkhp(row, [m for m in METHODS if not processed(m)])
    proc = best_rkhp(row, [m for m in METHODS if processed(m)])
    if plain is None or proc is None:
        return "-"
    return f"{row.cells[plain][1] / row.cells[proc][1]:.2f} ({plain} / {proc})"


def _ms(cell, index: int = 1) -> str:
    return "-" if cell is None else f"{cell[index] * 1e3:.3f}"


def _ratio(a, b) -> str:
    return "-" if a is None or b is None else f"{a[1] / b[1]:.2f}"


def line(row: Row, absent: dict) -> str:
    best = best_rkhp(row)
    ours = row.cells.get(best)
    parts = [f"{row.system:16s} {row.target:6.0e}  rkhp {best or '-'} {ours[0] if ours else ''} {_ms(ours)} ms"]
    for p in PEERS:
        parts.append(f"{p} absent" if p in absent else f"{p} {_ms(row.cells.get(p))} ms")
    parts.append(f"rkhp/dop853-compiled {_ratio(ours, row.cells.get('numbalsoda:dop853'))}")
    parts.append(f"scipy/rkhp {_ratio(row.cells.get('scipy:dop853'), ours)}")
    parts.append(f"plain/processed {gain(row)}")
    return "  ".join(parts)


def table(rows: list[Row], absent: dict, index: int) -> list[str]:
    """The markdown table of the rows: times in ms (CPU: index 1, wall: index 2) and the ratios."""
    head = ["system", "error", "rkhp best (setting)", "rkhp", *PEERS, "rkhp / compiled DOP853",
            "scipy DOP853 / rkhp", "best plain / best processed composition (CPU)"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        best = best_rkhp(row)
        ours = row.cells.get(best)
        cells = [f"`{row.system}`", f"{row.target:.0e}", f"{best} ({ours[0]})" if ours else "-", _ms(ours, index)]
        cells += ["absent" if p in absent else _ms(row.cells.get(p), index) for p in PEERS]
        dop, plain = row.cells.get("numbalsoda:dop853"), row.cells.get("scipy:dop853")
        cells += ["-" if ours is None or dop is None else f"{ours[index] / dop[index]:.1f}",
                  "-" if ours is None or plain is None else f"{plain[index] / ours[index]:.2f}", gain(row)]
        out.append("| " + " | ".join(cells) + " |")
    return out


def settings_table(rows: list[Row], absent: dict) -> list[str]:
    """The markdown table of every contender's setting and error per row."""
    names = [*METHODS, *PEERS]
    out = ["| system | error | " + " | ".join(names) + " |", "|" + "---|" * (len(names) + 2)]
    for row in rows:
        cells = [f"`{row.system}`", f"{row.target:.0e}"]
        for name in names:
            cell = row.cells.get(name)
            cells.append("absent" if name in absent else "-" if cell is None else f"{cell[0]}, {cell[3]:.1e}")
        out.append("| " + " | ".join(cells) + " |")
    return out


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for text in Path("/proc/cpuinfo").read_text().splitlines():
            if text.startswith("model name"):
                model = text.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "-"
    return f"{model}, {os.cpu_count()} cores, load average {load} at the start; Python {platform.python_version()}"


def versions() -> str:
    from importlib.metadata import PackageNotFoundError, version

    out = []
    for package in ("numpy", "scipy", "numba", "numbalsoda", "jax", "diffrax"):
        try:
            out.append(f"{package} {version(package)}")
        except PackageNotFoundError:
            out.append(f"{package} absent")
    return ", ".join(out)


def page(command: str, started: str, where: str, rows: list[Row], absent: dict, targets, rounds: int,
         processes: int = 1) -> str:
    """The generated results page (docs/results/work-precision.md)."""
    text = [
        "# Work-precision against compiled peers (generated)",
        "",
        "Generated by `benchmarks/work_precision.py`; do not edit by hand: run it again.",
        "",
        f"- command: `{command}`",
        f"- date: {started}",
        f"- machine: {where}",
        f"- packages: {versions()}",
        f"- T = {T_FINAL:g}; end-point error (2-norm) at most {', '.join(f'{t:.0e}' for t in targets)} against the "
        "best reference (closed form for the rigid body, else the tighter of scipy's DOP853 and the compiled "
        "DOP853 at rtol 1e-15 cross-checked at 1e-14); each contender at its cheapest setting (steps on a grid "
        "of ratio 2^(1/4), rtol on a grid of ratio 10^(1/4), atol = 1e-3 rtol).",
        f"- times in ms per call, warm (compile and trace left out), {rounds} interleaved rounds, minimum"
        + (f" over the rounds of {processes} processes run one after another" if processes > 1 else "")
        + f"; short calls repeated within a timing to last {BATCH_SECONDS * 1e3:g} ms.",
        "- rkhp: the best of " + ", ".join(METHODS) + "; numbalsoda:dop853: Hairer's DOP853 (Fortran) on a numba "
        "cfunc field; diffrax: under jax.jit on the CPU, float64; scipy:dop853: solve_ivp on the field written "
        "with plain arithmetic. Every field is generated from the system (rkhp.systems.field_code).",
    ]
    text += [f"- {reason}" for reason in absent.values()]
    text += ["", "## CPU time of the calling thread (ms)", "", *table(rows, absent, 1), "",
             "## Wall time (ms)", "", *table(rows, absent, 2), "",
             "## Settings (rkhp: steps; peers: rtol) and end-point errors", "", *settings_table(rows, absent), ""]
    return "\n".join(text)


def parser(program: str, doc: str) -> argparse.ArgumentParser:
    """An argument parser for a benchmark script whose --help prints its module docstring `doc`."""
    return argparse.ArgumentParser(prog=program, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)


def target_list(text: str) -> tuple[float, ...]:
    """--targets: end-point errors separated by commas, each in (0, 1)."""
    try:
        targets = tuple(float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of numbers: {text!r}") from None
    if not all(0 < t < 1 for t in targets):
        raise argparse.ArgumentTypeError(f"each target error must lie in (0, 1): {text!r}")
    return targets


def count_from_1_to(most: int):
    """The type of a count option: an integer from 1 to `most` (argparse's error otherwise)."""
    def count(text: str) -> int:
        if not text.isdigit() or not 1 <= int(text) <= most:
            raise argparse.ArgumentTypeError(f"not an integer from 1 to {most}: {text!r}")
        return int(text)

    return count


def arguments(argv) -> argparse.Namespace:
    """The command line (see the module)."""
    p = parser("python benchmarks/work_precision.py", __doc__)
    p.add_argument("systems", nargs="*", metavar="SYSTEM", help="built-in names or spec files")
    p.add_argument("--quick", action="store_true", help="the first system, 3 rounds")
    p.add_argument("--targets", type=target_list, default=TARGETS, help="end-point errors, comma separated")
    p.add_argument("--rounds", type=count_from_1_to(1000), metavar="N", help="interleaved rounds")
    p.add_argument("--processes", type=count_from_1_to(20), default=1, metavar="K",
                   help="run the race in K processes, each time their minimum (default 1)")
    p.add_argument("--write", metavar="PAGE", help="write the page here")
    p.add_argument("--rows-json", metavar="PATH", help=argparse.SUPPRESS)  # a process of --processes
    return p.parse_args(argv)


def main(argv) -> None:
    argv = list(argv)
    command = " ".join(["python benchmarks/work_precision.py", *argv])
    args = arguments(argv)
    targets, quick, write = args.targets, args.quick, args.write
    rounds = args.rounds or (3 if quick else ROUNDS)
    systems = tuple(args.systems) or (SYSTEMS[:1] if quick else SYSTEMS)
    started = time.strftime("%Y-%m-%d %H:%M")
    where = machine()
    print(f"# {command}  ({started}; {where})")
    print(f"# T = {T_FINAL:g}; cheapest setting per target; min of {rounds} interleaved warm rounds, "
          "ms per call, CPU time of the calling thread")
    absent = {p: reason for p in PEERS if (reason := P.absent(peer_of(p)))}
    for reason in absent.values():
        print(reason)
    if args.processes > 1:
        child = [*args.systems, *(["--quick"] if quick else []), "--targets", ",".join(map(repr, targets)),
                 "--rounds", str(rounds)]
        rows = in_processes(child, args.processes)
        print(f"# the minimum over {args.processes} processes")
        for row in rows:
            print(line(row, absent))
    else:
        rows = []
        for name in systems:
            rows += race(name, targets, rounds, absent)
    if args.rows_json:
        Path(args.rows_json).write_text(json.dumps(row_records(rows)))
    if write:
        Path(write).write_text(page(command, started, where, rows, absent, targets, rounds, args.processes))
        print(f"# written: {write}")


def run_script(main_function, argv) -> None:
    """main_function(argv), a bad system name or spec file reported in one line (exit 2)."""
    from rkhp.base.errors import InputError

    try:
        main_function(argv)
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    run_script(main, sys.argv[1:])
