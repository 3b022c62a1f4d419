"""RKHP integration of a Poisson system with any tableau, explicit or implicit (paper §5.2;
docs/theory.md §10): the Python API.

`integrate(system, tableau, h, n_steps, x0=None)` runs the compiled loop of
`rkhp.integrators.engine` and returns a :class:`Trajectory`; `integrate_ensemble` runs many
initial conditions at once (threads over the compiled loop, which releases the GIL). Compile
time (first call in a process: compiling, or loading numba's cache) is measured apart from run
time.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..base.bounds import check_step
from ..base.errors import InputError, NumericalFailure
from ..base.executors import available_cores, run_all
from .failure import Failure, failure_status
from .newton import NEWTON_MAX_ITERATIONS, NEWTON_TOLERANCE, STAGE_MAX_SWEEPS
from .trajectory import Trajectory, checked

MAX_PRODUCT_PAIRS = 2_000_000
"""Largest product table the Taylor tower accepts (n variables, degree s + 1 for an explicit
tableau, `implicit_degree` for an implicit one)."""


def resolve_tableau(tableau):
    """A Tableau from a Tableau, a built-in name or a file path."""
    if isinstance(tableau, str):
        from ..tableaux.files import load_tableau

        return load_tableau(tableau)
    return tableau


def tableau_arrays(tableau) -> tuple[np.ndarray, np.ndarray]:
    """The float64 (A, b) of a tableau."""
    A = np.ascontiguousarray(tableau.A_float, dtype=np.float64)
    b = np.ascontiguousarray(tableau.b_float, dtype=np.float64)
    return A, b


def is_implicit(A: np.ndarray) -> bool:
    """Whether a stage depends on itself or a later one (an entry on or above the diagonal)."""
    return bool(np.any(np.triu(A) != 0.0))


def stage_solve(tableau, A, degree=None, max_sweeps=STAGE_MAX_SWEEPS):
    """The StageSolve of a tableau: explicit (degree 0) or implicit with stage functions that are
    jets of degree `degree` (default: `implicit_degree`)."""
    from .engine import StageSolve

    if not is_implicit(A):
        return StageSolve(0, int(max_sweeps))
    if degree is None:
        from ..tableaux.verification import class_orders

        degree = implicit_degree(max(class_orders(tableau, "float").values()))
    if int(degree) != degree or degree < 1:
        raise InputError(f"the stage degree must be a positive integer, got {degree!r}")
    return StageSolve(int(degree), int(max_sweeps))


def compiled_stage(stage):
    """What the compiled loop takes for `stage`: None for an explicit tableau, so that numba
    compiles the loop of explicit tableaux without the implicit tower (docs/engine.md "Compile
    time"), the StageSolve itself for an implicit one."""
    return stage if stage.degree > 0 else None


def implicit_degree(order: int) -> int:
    """Jet degree D of the stage functions of an implicit method of order N (its highest over the
    condition classes): D = N + 1, at least 2 (the Newton Jacobian needs degree-1 coefficients of
    the gradients).

    Truncating the stage functions g_j at degree D leaves the degree-k coefficients of their
    gradients wrong by O(h^(D - k)) (one degree and one power of h per gradient, from the missing
    degree-D coefficients of Z), so psi = h sum_i b_i grad g_i(x) is wrong by O(h^(D + 1)) and the
    global error by O(h^D): D = N + 1 keeps it one order below the method's (measured in
    docs/implicit.md; docs/theory.md §10).
    """
    return max(order + 1, 2)


def engine_data(system, stages: int, stage):
    """`rkhp.integrators.engine.EngineData`: the tapes, interpreter and jet space for the
    compiled engine, jets in n variables of degree s + 1 (explicit) or the stage degree
    (implicit)."""
    from ..taylor.interpreter import as_plain, interpreter
    from ..taylor.jets import jet_space
    from .engine import EngineData, SystemTapes

    degree = stage.degree if stage.degree > 0 else stages + 1
    space = jet_space(system.dim, degree)
    if len(space.pa) > MAX_PRODUCT_PAIRS:
        raise InputError(f"the method needs Taylor polynomials of degree {degree} in "
                         f"{system.dim} variables ({len(space.pa)} product terms): too large")
    plain = [as_plain(t) for t in (system.f_tape, system.h_tape, system.alpha_tape, system.beta_tape)]
    return EngineData(SystemTapes(*plain), interpreter(system.f_tape), space)


def integrate(system, tableau, h, n_steps, x0=None, *, tol: float = NEWTON_TOLERANCE,
              max_iter: int = NEWTON_MAX_ITERATIONS, stage_degree: int | None = None) -> Trajectory:
    """Integrate `system` with the RKHP method of `tableau`, explicit or implicit (paper §5.2;
    docs/theory.md §5, §10).

    For an implicit tableau the stage functions are jets of degree `stage_degree` (default
    `implicit_degree` of the tableau's order), solved as accurately as Newton solves x (`tol`).
    Returns a Trajectory with states y_0..y_k, Newton iterations and stage sweeps per step, and a
    status naming the failing step, time and cause if a step failed (then only the states before
    it are kept).
    """
    from .engine import Method, Record, Solver, rkhp_run, step_buffers

    tableau = resolve_tableau(tableau)
    h, n_steps = check_step(h, n_steps, system.dim)
    y0 = system.start(x0)
    A, b = tableau_arrays(tableau)
    stage = stage_solve(tableau, A, stage_degree)
    tapes, interpreter, space = engine_data(system, len(b), stage)
    buf = step_buffers(tapes, system.dim, len(b), space, stage.degree)
    method, solver = Method(A, b, h), Solver(float(tol), int(max_iter), system.domain_code)
    t0 = time.perf_counter()
    rest = (interpreter.address, tapes, space, buf, solver, compiled_stage(stage))
    one = np.zeros(1, np.int64)
    rkhp_run(y0, method, 0, *rest, Record(np.zeros((1, y0.size)), one, True, one))
    compile_seconds = time.perf_counter() - t0
    states = np.empty((n_steps + 1, y0.size))
    iterations = np.zeros(max(n_steps, 1), dtype=np.int64)
    sweeps = np.zeros(max(n_steps, 1), dtype=np.int64)
    t0 = time.perf_counter()
    done, cause = rkhp_run(y0, method, n_steps, *rest, Record(states, iterations, True, sweeps))
    run_seconds = time.perf_counter() - t0
    failed = cause != Failure.OK
    return checked(Trajectory(
        times=h * np.arange(done + 1), states=states[: done + 1],
        newton_iterations=iterations[: done + failed], stage_sweeps=sweeps[: done + failed],
        cause=cause, status=failure_status(cause, done, h, system.domain) if failed else "ok",
        failed_step=done if failed else None, compile_seconds=compile_seconds,
        run_seconds=run_seconds, method=getattr(tableau, "name", "custom"), system=system.name,
        extra={"newton_tolerance": tol, "newton_max_iterations": max_iter,
               "realisation": system.realisation, "stage_degree": stage.degree}, poisson=system), system)


def integrate_ensemble(system, tableau, h, n_steps, x0s, *, tol: float = NEWTON_TOLERANCE,
                       max_iter: int = NEWTON_MAX_ITERATIONS, threads: int | None = None,
                       executor=None, stage_degree: int | None = None) -> np.ndarray:
    """Final states of many trajectories at once (shape (m, n)), in `threads` threads (default:
    the CPUs available) running the compiled loop without the GIL (the "vmap"); with an
    `executor` (rkhp.base.executors), the starts are cut into one chunk per slot and each chunk runs so
    on a worker (same final states: each trajectory is computed on its own). NumericalFailure
    naming the first failing trajectory if any fails."""
    tableau = resolve_tableau(tableau)
    h, n_steps = check_step(h, n_steps)
    x0s = np.ascontiguousarray(x0s, dtype=np.float64)
    if x0s.ndim != 2 or x0s.shape[1] != system.dim:
        raise InputError(f"initial conditions must have shape (m, {system.dim}), got {x0s.shape}")
    for i, x in enumerate(x0s):
        if not system.in_domain(x):
            raise InputError(f"initial condition {i} = {x.tolist()} is outside the domain")
    A, b = tableau_arrays(tableau)
    settings = (float(tol), int(max_iter), stage_solve(tableau, A, stage_degree), threads)
    if executor is None:
        finals, done, causes = _ensemble_chunk(system, A, b, h, n_steps, x0s, *settings)
    else:
        chunks = np.array_split(x0s, max(1, min(len(x0s), executor.slots)))
        parts = run_all(executor, _ensemble_chunk, [(system, A, b, h, n_steps, c, *settings) for c in chunks])
        finals, done, causes = (np.concatenate([p[k] for p in parts]) for k in range(3))
    bad = np.flatnonzero(causes)
    if bad.size:
        i = int(bad[0])
        raise NumericalFailure(f"trajectory {i} of {len(x0s)}: "
                               + failure_status(Failure(causes[i]), int(done[i]), h, system.domain))
    return finals


def _ensemble_chunk(system, A, b, h, n_steps, x0s, tol, max_iter, stage, threads):
    """(final states, steps done, Failure codes) of the trajectories from ``x0s``, in threads."""
    from .engine import Method, Record, Solver, rkhp_run, step_buffers

    tapes, interpreter, space = engine_data(system, len(b), stage)
    run = interpreter.address
    method, solver = Method(A, b, h), Solver(tol, max_iter, system.domain_code)
    m = len(x0s)
    finals = np.zeros_like(x0s)
    done = np.zeros(m, dtype=np.int64)
    codes = np.zeros(m, dtype=np.int64)
    threads = threads or available_cores()
    bounds = np.linspace(0, m, min(threads, max(m, 1)) + 1).astype(int)

    def batch(lo, hi):
        last = np.zeros((1, system.dim))
        iterations = np.zeros(max(n_steps, 1), dtype=np.int64)
        sweeps = np.zeros(max(n_steps, 1), dtype=np.int64)
        buf = step_buffers(tapes, system.dim, len(b), space, stage.degree)
        record = Record(last, iterations, False, sweeps)
        for t in range(lo, hi):
            done[t], codes[t] = rkhp_run(x0s[t], method, n_steps, run, tapes, space, buf, solver,
                                         compiled_stage(stage), record)
            finals[t] = last[0]

    with ThreadPoolExecutor(max_workers=len(bounds) - 1) as pool:
        list(pool.map(batch, bounds[:-1], bounds[1:]))
    return finals, done, codes
