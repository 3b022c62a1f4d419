"""Cost of a step of the Taylor Hamiltonian Poisson integrators (rkhp.integrators.taylor), this
checkout against another version (prints measured figures; run: python benchmarks/thp.py
[--before COMMIT] [--rounds N]).

Cases (`CASES`): thp4 on the rigid body and thp3 on the periodic Toda lattice of size 6 (n = 6),
h = 0.1, 100 steps from the default start. Each version is a copy of rkhp (`compile.assemble`:
the version to compare with from `git archive COMMIT`, default the commit before THP ran on the
driver; this checkout's working tree as "after") run in a fresh process of this Python with
PYTHONPATH set to its copy and a numba cache of its own (filled by a first, untimed process). A
process runs each case once (compiled or loaded), then REPEATS times: CPU seconds of the calling
thread (`time.thread_time`) of `Method.integrate`, the whole call; the minimum over its repeats,
per step. The versions' processes alternate, `--rounds` rounds, and the minimum over the rounds
is printed, with the final states' largest difference relative to max(1, |y|).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compile import assemble  # noqa: E402

BEFORE = "decc71b"
CASES = (("rigid-body", "thp4"), ("toda:6", "thp3"))
STEPS = 100
H = 0.1
REPEATS = 5

CODE = """
import json, sys, time
from rkhp.integrators.methods import resolve_method, resolve_system
cases, h, steps, repeats = json.loads(sys.argv[1])
out = {}
for name, method in cases:
    system, m = resolve_system(name), resolve_method(method)
    m.integrate(system, h, 2)
    best = float("inf")
    for _ in range(repeats):
        start = time.thread_time()
        final = m.integrate(system, h, steps).raise_if_failed().states[-1]
        best = min(best, time.thread_time() - start)
    out[name + " " + method] = [best / steps * 1e6, final.tolist()]
print(json.dumps(out))
"""


def run(tree: Path, cache: Path) -> dict:
    """{case: [us per step, final state]} of one process of a version."""
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.run([sys.executable, "-c", CODE, json.dumps([CASES, H, STEPS, REPEATS])], env=env,
                          capture_output=True, text=True, cwd=tree)
    if proc.returncode != 0:
        raise RuntimeError(f"{tree} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=BEFORE)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        trees = {"before": assemble(work / "before", args.before), "after": assemble(work / "after", None)}
        for label, tree in trees.items():
            run(tree, work / f"cache-{label}")  # compiles: not timed
        rounds = {label: [] for label in trees}
        for _ in range(args.rounds):
            for label, tree in trees.items():
                rounds[label].append(run(tree, work / f"cache-{label}"))
    print(f"THP, h = {H}, {STEPS} steps: us per step (thread CPU, min over {args.rounds} rounds x {REPEATS})")
    print(f"{'case':22} {'before ' + args.before:>16} {'after':>10} {'ratio':>7} {'final diff':>11}")
    for name, method in CASES:
        case = f"{name} {method}"
        before = min(r[case][0] for r in rounds["before"])
        after = min(r[case][0] for r in rounds["after"])
        a, b = (rounds[label][0][case][1] for label in ("before", "after"))
        diff = max(abs(x - y) for x, y in zip(a, b, strict=True)) / max(1.0, max(abs(x) for x in a))
        print(f"{case:22} {before:16.1f} {after:10.1f} {before / after:7.1f} {diff:11.1e}")


if __name__ == "__main__":
    main()
