"""Where the cold compile of `rkhp compile` goes: each of its parts (a class of tapes x a kind of
run, `rkhp.integrators.ahead.AHEAD_PARTS`) compiled in turn, in one fresh process with an empty
numba cache, in the order `rkhp compile` gives them (each class's Hamiltonian first, which
compiles the class's tape interpreter; each figure leaves out what the parts before it compiled).

Run: python benchmarks/compile_parts.py

Prints, per part, the wall and CPU seconds of the process that ran it, then the sums per class and
per kind of run, and the load average. docs/engine.md "Compile time" shows a run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

PARTS_CODE = """
import json
from rkhp.integrators.ahead import ahead_phases, tape_classes, timed_part
for task in [task for phase in ahead_phases(tape_classes()) for task in phase]:
    spent = timed_part(task.system, task.part)
    print(json.dumps({"system": task.system, "part": task.part, "seconds": spent.seconds,
                      "cpu_seconds": spent.cpu_seconds}), flush=True)
"""


def measure() -> list[dict]:
    """The parts' times, from a fresh process whose numba cache is a new empty folder."""
    with tempfile.TemporaryDirectory(prefix="rkhp-parts-") as cache:
        out = subprocess.run([sys.executable, "-c", PARTS_CODE], capture_output=True, text=True, check=True,
                             env=dict(os.environ, NUMBA_CACHE_DIR=cache))
    return [json.loads(line) for line in out.stdout.splitlines()]


def sums(rows: list[dict], key: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for row in rows:
        out[row[key]] = out.get(row[key], 0.0) + row["cpu_seconds"]
    return out


def main() -> None:
    rows = measure()
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} after the run")
    print(f"{'system':18s} {'part':18s} {'wall s':>8s} {'CPU s':>8s}")
    for row in rows:
        print(f"{row['system']:18s} {row['part']:18s} {row['seconds']:8.2f} {row['cpu_seconds']:8.2f}")
    total = sum(row["cpu_seconds"] for row in rows)
    print(f"total CPU {total:.1f} s")
    for key in ("system", "part"):
        print(f"CPU per {key}: " + ", ".join(f"{name} {cpu:.1f} s ({cpu / total:.0%})"
                                           for name, cpu in sorted(sums(rows, key).items(), key=lambda kv: -kv[1])))


if __name__ == "__main__":
    from work_precision import parser

    parser("python benchmarks/compile_parts.py", __doc__).parse_args()
    main()
