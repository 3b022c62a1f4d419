"""How `rkhp compile` keeps its processes busy: the parts (`rkhp.integrators.ahead.ahead_phases`)
run phase after phase in two processes, as `rkhp compile` runs them, on an empty numba cache, and
each part's start and end (seconds from the start of the run) and CPU seconds are printed, with
the end of each phase: the compiling phase ends when its longest chain of parts does.

Run: python benchmarks/compile_schedule.py [--jobs N]

docs/engine.md "Compile time" shows a run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

SCHEDULE_CODE = """
import json, sys, time
from rkhp.base.executors import LocalProcesses, run_all
from rkhp.integrators.ahead import ahead_phases, tape_classes, timed_part

def timed(system, part):
    start = time.time()
    spent = timed_part(system, part)
    return {"system": system, "part": part, "start": start, "end": time.time(), "cpu_seconds": spent.cpu_seconds}

origin = time.time()
executor = LocalProcesses(int(sys.argv[1]))
try:
    for number, phase in enumerate(ahead_phases(tape_classes()), start=1):
        for row in run_all(executor, timed, phase):
            print(json.dumps({**row, "phase": number, "start": row["start"] - origin, "end": row["end"] - origin}))
        print(json.dumps({"phase": number, "phase_end": time.time() - origin}), flush=True)
finally:
    executor.close()
"""


def measure(jobs: int) -> list[dict]:
    """The parts' times, from a fresh process whose numba cache is a new empty folder."""
    with tempfile.TemporaryDirectory(prefix="rkhp-schedule-") as cache:
        out = subprocess.run([sys.executable, "-c", SCHEDULE_CODE, str(jobs)], capture_output=True, text=True,
                             check=True, env=dict(os.environ, NUMBA_CACHE_DIR=cache))
    return [json.loads(line) for line in out.stdout.splitlines()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    options = parser.parse_args()
    rows = measure(options.jobs)
    print(f"{'system':18s} {'part':18s} {'start':>7s} {'end':>7s} {'CPU':>7s}")
    for row in rows:
        if "phase_end" in row:
            print(f"phase {row['phase']} ends at {row['phase_end']:.1f} s")
        else:
            print(f"{row['system']:18s} {row['part']:18s} {row['start']:6.1f}s {row['end']:6.1f}s "
                  f"{row['cpu_seconds']:6.1f}s")
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
