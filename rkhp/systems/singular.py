"""Where the flow of a system stops: the structure pi(x) or grad H(x) blowing up along it, or the
state leaving its domain (docs/exit-status.md). A failed step of an integrator is reported with
this cause when the exact flow itself does not continue over the step."""

from __future__ import annotations

import numpy as np

#: the probe of the exact flow over the failed step: scipy's DOP853 at these tolerances
PROBE_RTOL, PROBE_ATOL = 1e-10, 1e-12
#: a factor of growth of |pi| or |grad H| over the step that names it as the cause
GROWTH = 10.0


def _norm(value) -> float:
    value = np.asarray(value, dtype=np.float64)
    return float(np.linalg.norm(value)) if np.all(np.isfinite(value)) else float("inf")


def _vector(x) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in x) + ")"


def flow_stop(system, x, h: float) -> str | None:
    """Why the exact flow of `system` does not continue from `x` over a step of `h`, in words, or
    None when it does. DOP853 (PROBE_RTOL) from x over h; where it stops short, fails or leaves the
    domain, the last state it reached is compared with x: |pi| or |grad H| grown by GROWTH or more
    (or not finite) is named as the cause."""
    from scipy.integrate import solve_ivp

    x = np.asarray(x, dtype=np.float64)
    with np.errstate(all="ignore"):
        try:
            sol = solve_ivp(lambda t, y: system.vector_field(y), (0.0, float(h)), x, method="DOP853",
                            rtol=PROBE_RTOL, atol=PROBE_ATOL)
        except (ValueError, ArithmeticError):
            sol = None
        states = [] if sol is None else [(t, y) for t, y in zip(sol.t, sol.y.T, strict=True)
                                         if np.all(np.isfinite(y)) and system.in_domain(y)]
        done = sol is not None and sol.status == 0 and len(states) == len(sol.t)
        if done:
            return None
        t, y = states[-1] if states else (0.0, x)
        growth = {"the structure pi": (_norm(system.poisson(y)), _norm(system.poisson(x))),
                  "grad H": (_norm(system.grad_hamiltonian(y)), _norm(system.grad_hamiltonian(x)))}
    where = f"the exact flow stops {t:.3g} into the step, at x = {_vector(y)}"
    causes = [f"{name} blows up there (|{name.split()[-1]}| = {end:.3g}, {start:.3g} at the step's start)"
              for name, (end, start) in growth.items() if end >= GROWTH * max(start, 1e-300)]
    if not system.in_domain(y) or (sol is not None and len(states) < len(sol.t) and not causes):
        causes.append(f"it leaves the domain ({system.domain})")
    return f"{where}: {'; '.join(causes)}" if causes else where
