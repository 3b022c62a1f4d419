"""RKHP integration of a Poisson system with any tableau, explicit or implicit, by the Taylor tower
(paper §5.2; docs/theory.md §5, §10): the Python API of the tower's substeps run by the driver.

`integrate_rkhp(system, tableau, h, n_steps, x0=None)` returns a :class:`Trajectory`;
`integrate_ensemble` runs many initial conditions at once (threads over the compiled loop, which
releases the GIL). Compile time (first call in a process: compiling, or loading numba's cache) is
measured apart from run time. A method by name (`rkhp.integrators.methods.integrate`) runs on the
provider the table of `rkhp.integrators.substeps` chooses, which for RKHP Euler on some families
is a direct form rather than the tower.
"""

from __future__ import annotations

import numpy as np

from .driver import run, run_ensemble
from .newton import NEWTON_MAX_ITERATIONS, NEWTON_TOLERANCE
from .substeps import TOWER
from .tower_substep import resolve_tableau
from .trajectory import Trajectory


def integrate_rkhp(system, tableau, h, n_steps, x0=None, *, tol: float = NEWTON_TOLERANCE,
              max_iter: int = NEWTON_MAX_ITERATIONS, stage_degree: int | None = None) -> Trajectory:
    """Integrate `system` with the RKHP method of `tableau`, explicit or implicit (paper §5.2;
    docs/theory.md §5, §10), by the Taylor tower.

    For an implicit tableau the stage functions are jets of degree `stage_degree` (default
    `tower_substep.implicit_degree` of the tableau's order), solved as accurately as Newton solves
    x (`tol`). Returns a Trajectory with states y_0..y_k, Newton iterations and stage sweeps per
    step, and a status naming the failing step, time and cause if a step failed (then only the
    states before it are kept).
    """
    tableau = resolve_tableau(tableau)
    return run(system, tableau, h, n_steps, x0, provider=TOWER, tol=tol, max_iter=max_iter,
               options={"stage_degree": stage_degree})


def integrate_ensemble(system, tableau, h, n_steps, x0s, *, tol: float = NEWTON_TOLERANCE,
                       max_iter: int = NEWTON_MAX_ITERATIONS, threads: int | None = None,
                       executor=None, stage_degree: int | None = None) -> np.ndarray:
    """Final states of many trajectories of `integrate_rkhp` at once (shape (m, n)), in `threads`
    threads (default: the CPUs available) running the compiled loop without the GIL (the "vmap");
    with an `executor` (rkhp.base.executors), the starts are cut into one chunk per slot and each
    chunk runs so on a worker (same final states: each trajectory is computed on its own).
    NumericalFailure naming the first failing trajectory if any fails."""
    return run_ensemble(system, resolve_tableau(tableau), h, n_steps, x0s, provider=TOWER, tol=tol,
                        max_iter=max_iter, options={"stage_degree": stage_degree}, threads=threads,
                        executor=executor)
