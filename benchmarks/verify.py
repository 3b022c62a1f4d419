"""Timings of `rkhp verify` (issue 3 targets) and, where installed, of nodepy's order().

Targets: complete float check of Feagin 14(12) <= 0.5 s; the same at 60 digits <= 30 s; exact
check of each of the paper's methods <= 1 s. Each measurement runs in a fresh interpreter, so
that "cold" includes the lazy imports (sympy for exact radicals) and the tree enumeration; "warm"
repeats the call in the same process (trees and plan cached). Wall-clock times, best of the
repeats shown. Run: `.venv/bin/python benchmarks/verify.py [--quick]` (--quick skips 60 digits).
"""

from __future__ import annotations

import json
import subprocess
import sys

CHILD = r"""
import json, sys, time
name, precision, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3])
precision = None if precision == "default" else (int(precision) if precision.isdigit() else precision)
from rkhp.tableaux.verification import verify
times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    v = verify(name, precision=precision)
    times.append(time.perf_counter() - t0)
print(json.dumps({"cold": times[0], "warm": min(times[1:]) if repeats > 1 else None,
                  "order": v.order, "degenerate_order": v.degenerate_order,
                  "precision": v.precision, "checked": v.conditions_checked["general"]}))
"""

NODEPY = r"""
import json, sys, time
import numpy as np
from nodepy import rk
from rkhp.tableaux.files import load_tableau
t = load_tableau(sys.argv[1])
method = rk.ExplicitRungeKuttaMethod(np.array(t.A_float), np.array(t.b_float))
t0 = time.perf_counter()
order = method.order()
print(json.dumps({"time": time.perf_counter() - t0, "order": int(order)}))
"""


def run(code: str, *args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         timeout=900)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "failed"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def show(label: str, r: dict, target: float | None = None) -> None:
    if "error" in r:
        print(f"{label:48s} error: {r['error']}")
        return
    warm = f", warm {r['warm']:.3f} s" if r.get("warm") is not None else ""
    goal = f"  [target <= {target:g} s]" if target else ""
    print(f"{label:48s} cold {r['cold']:.3f} s{warm}  order {r['order']}/{r['degenerate_order']}"
          f" ({r['precision']}, {r['checked']} general conditions checked){goal}")


def main() -> None:
    from work_precision import parser

    p = parser("python benchmarks/verify.py", __doc__)
    p.add_argument("--quick", action="store_true", help="skip the checks at 60 digits")
    quick = p.parse_args().quick
    print("rkhp verify (wall clock; order shown as general/degenerate)")
    show("feagin14, float, every tree up to order 15", run(CHILD, "feagin14", "float", "4"), 0.5)
    if not quick:
        show("feagin14, 60 digits, every tree up to order 15", run(CHILD, "feagin14", "default", "1"),
             30)
    for name in ("euler", "paper-two-stage", "paper-three-stage", "paper-implicit"):
        show(f"{name}, exact", run(CHILD, name, "exact", "3"), 1.0)
    for name in ("gauss3", "dop853", "feagin10", "feagin12"):
        show(f"{name}, default precision", run(CHILD, name, "default", "2"))
    try:
        import nodepy.runge_kutta_method  # noqa: F401
    except ImportError as exc:
        print(f"nodepy not importable ({exc}; pip install -e '.[bench]'): no comparison")
        return
    print("nodepy order() on the same float64 coefficients (its default tolerance)")
    for name in ("rk4", "dop853", "feagin10", "feagin12", "feagin14"):
        r = run(NODEPY, name)
        if "error" in r:
            print(f"  {name:12s} error: {r['error']}")
        else:
            print(f"  {name:12s} {r['time']:.3f} s  order {r['order']}")


if __name__ == "__main__":
    main()
