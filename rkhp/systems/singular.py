"""Where the flow of a system stops: the structure pi(x) or grad H(x) blowing up along it, or the
state leaving its domain (docs/exit-status.md). A failed step of an integrator is reported with
this cause when the exact flow itself does not continue over the step."""

from __future__ import annotations

import math

import numpy as np

#: the probe of the exact flow over the failed step: scipy's DOP853 at these tolerances
PROBE_RTOL, PROBE_ATOL = 1e-10, 1e-12
#: a factor of growth of |pi| or |grad H| over the step that names it as the cause
GROWTH = 10.0
#: the probe takes at most this many steps: a flow that needs more over the failed step is
#: regular enough there (a step far too large), and no cause is added
PROBE_STEPS = 2000


def _norm(value) -> float:
    value = np.asarray(value, dtype=np.float64)
    return float(np.linalg.norm(value)) if np.all(np.isfinite(value)) else float("inf")


def _vector(x) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in x) + ")"


def _probe_field(system):
    """The field as the probe calls it, (t, x) -> pi(x) grad H(x), raising FloatingPointError at
    a time that is not a number: scipy's step size becomes NaN where the field is not finite at a
    step's start (inf - inf), and its loop of tries of a step, which ends on a size too small,
    would then not end."""
    def probe_field(t, v):
        if not math.isfinite(t):
            raise FloatingPointError("the probe's step size is not a number")
        return system.vector_field(v)

    return probe_field


def flow_stop(system, x, h: float) -> str | None:
    """Why the exact flow of `system` does not continue from `x` over a step of `h`, in words, or
    None when it does (or when PROBE_STEPS steps do not tell). DOP853 (PROBE_RTOL) from x over h;
    where it fails or leaves the domain, the last state it reached is compared with x: |pi| or
    |grad H| grown by GROWTH or more (or not finite) is named as the cause."""
    from scipy.integrate import DOP853

    x = np.asarray(x, dtype=np.float64)
    t, y, stopped, left = 0.0, x, False, False
    with np.errstate(all="ignore"):
        try:
            solver = DOP853(_probe_field(system), 0.0, x, float(h), rtol=PROBE_RTOL, atol=PROBE_ATOL)
            for _ in range(PROBE_STEPS):
                solver.step()
                if not (np.all(np.isfinite(solver.y)) and system.in_domain(solver.y)):
                    stopped, left = True, bool(np.all(np.isfinite(solver.y)))
                    break
                t, y = solver.t, np.array(solver.y)
                if solver.status != "running":
                    stopped = solver.status == "failed"
                    break
        except (ValueError, ArithmeticError):
            stopped = True
        if not stopped:
            return None
        growth = {"the structure pi": (_norm(system.poisson(y)), _norm(system.poisson(x))),
                  "grad H": (_norm(system.grad_hamiltonian(y)), _norm(system.grad_hamiltonian(x)))}
    where = f"the exact flow stops {t:.3g} into the step, at x = {_vector(y)}"
    causes = [f"{name} blows up there (|{name.split()[-1]}| = {end:.3g}, {start:.3g} at the step's start)"
              for name, (end, start) in growth.items() if end >= GROWTH * max(start, 1e-300)]
    if left:
        causes.append(f"it leaves the domain ({system.domain}) next")
    return f"{where}: {'; '.join(causes)}" if causes else where
