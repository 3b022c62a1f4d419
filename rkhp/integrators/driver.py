"""The one driver of the RKHP integrators: the step loop over substeps gamma_1 h, ..., gamma_s h of a
base method, whatever provider computes them (docs/engine.md "One driver, many substeps",
docs/theory.md §12).

A step of size h is the substeps gamma_1 h, ..., gamma_s h in turn (a tableau alone: s = 1,
gamma = (1)); a processed composition P^-1 o K^n o P (docs/theory.md §12) has its processor's
substeps first in the coefficients and its inverse's last: those run once before the first step
and once at each state the run keeps (its output), not at every step. Each substep is computed by the substep provider that `rkhp.integrators.substeps.choose` picks
for the system and the base method. `drive` is the compiled loop, written once: numba compiles it
once per provider (the class of the provider's data); it records the states, the Newton (or chord)
iterations and the stage sweeps of each step, summed over its substeps, and checks the state after
every substep (`rkhp.integrators.engine.state_failure`: finite, in the system's domain). `run`
is its Python entry (a :class:`~rkhp.integrators.trajectory.Trajectory`), `run_ensemble` runs many
initial values (threads over the compiled loop, which releases the GIL); `integrate_closed_euler`
and `integrate_spray_euler` run RKHP Euler and its compositions by a direct form.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from ..base.bounds import MAX_STAGES, check_step
from ..base.errors import InputError, NumericalFailure
from ..base.executors import available_cores, run_all
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from .engine import Solver, state_failure
from .failure import Failure, failure_status
from .newton import NEWTON_MAX_ITERATIONS
from .substeps import CLOSED, PROVIDERS, SPRAY, begin, choose, substep
from .trajectory import Trajectory, checked


class Record(NamedTuple):
    """Where a run writes: states (n_steps + 1, n) when every state is kept (states[k] = y_k), else
    (1, n) (the last state); per step, its Newton iterations and its stage sweeps (summed over its
    substeps); whether every state is kept."""

    states: np.ndarray
    iterations: np.ndarray
    sweeps: np.ndarray
    keep_all: bool


@nb.njit(**NJIT_NORC)
def drive(y0, gammas, processor, h, n_steps, data, solver, record):
    """n_steps steps of size h from y0 of the provider whose data is `data`
    (`rkhp.integrators.substeps`), substep i of a step warm-started from substep i of the steps
    before (the provider's memory, emptied by its ``begin``); the state is checked after every
    substep. Without a processor (`processor` = 0) a step is the substeps gammas[0] h,
    gammas[1] h, ...; with one, gammas holds the processor's `processor` coefficients, the
    kernel's and the inverse processor's (`rkhp.tableaux.compositions.one_step`): the processor's
    substeps (of size gammas[i] |h|) run once from y0, each step is the kernel's, and the inverse
    processor's run from each state kept (every state with `record.keep_all`, else the last).
    Returns (completed steps, Failure of the step after them or Failure.OK)."""
    context = begin(data, y0)
    n = y0.shape[0]
    for k in range(n):
        record.states[0, k] = y0[k]
    end = gammas.shape[0]
    cause, it, done = _substeps(data, context, gammas, 0, processor, abs(h), solver)
    if cause != Failure.OK:
        record.iterations[0] = it
        record.sweeps[0] = done
        return 0, cause
    steps, cause = _steps(data, context, gammas, processor, end - processor, h, n_steps, solver, record)
    record.iterations[0] += it
    record.sweeps[0] += done
    if processor == 0:
        return steps, cause
    first = 0 if not record.keep_all and steps > 0 else 1
    rows = steps + 1 if record.keep_all else 1
    for row in range(first, rows):
        context = begin(data, record.states[row])
        failed, it, done = _substeps(data, context, gammas, end - processor, end, abs(h), solver)
        if failed != Failure.OK:  # the output of this row failed: the run ends before it
            if not record.keep_all:
                for k in range(n):
                    record.states[0, k] = y0[k]
            return (row - 1 if record.keep_all else 0), failed
        at = row - 1 if record.keep_all else steps - 1
        record.iterations[at] += it
        record.sweeps[at] += done
        for k in range(n):
            record.states[row, k] = data.y[k]
    return steps, cause


@nb.njit(**NJIT_NORC)
def _substeps(data, context, gammas, lo, hi, h, solver):
    """Substeps lo .. hi - 1 of sizes gammas[i] h, the state checked after each; returns (Failure,
    iterations, stage sweeps)."""
    iterations = 0
    sweeps = 0
    for i in range(lo, hi):
        cause, it, done = substep(data, context, i, gammas[i] * h, solver)
        iterations += it
        sweeps += done
        if cause == Failure.OK:
            cause = state_failure(data.y, solver.domain)
        if cause != Failure.OK:
            return cause, iterations, sweeps
    return Failure.OK, iterations, sweeps


@nb.njit(**NJIT_NORC)
def _steps(data, context, gammas, lo, hi, h, n_steps, solver, record):
    """n_steps steps, each the substeps lo .. hi - 1 of sizes gammas[i] h, the states recorded;
    returns (completed steps, Failure of the step after them or Failure.OK)."""
    y = data.y
    n = y.shape[0]
    for step in range(n_steps):
        cause, iterations, sweeps = _substeps(data, context, gammas, lo, hi, h, solver)
        record.iterations[step] = iterations
        record.sweeps[step] = sweeps
        if cause != Failure.OK:
            return step, cause
        row = step + 1 if record.keep_all else 0
        for k in range(n):
            record.states[row, k] = y[k]
    return n_steps, Failure.OK


def check_gammas(gammas) -> np.ndarray:
    """The composition's coefficients as a float array (InputError unless 1 to MAX_STAGES finite
    numbers)."""
    try:
        g = np.array(gammas, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError("gammas must be a list of numbers") from None
    if not 1 <= g.size <= MAX_STAGES or not np.all(np.isfinite(g)):
        raise InputError(f"gammas must be 1 to {MAX_STAGES} finite numbers")
    return np.ascontiguousarray(g)


def record(n_steps: int, n: int, keep_all: bool) -> Record:
    """The arrays a run of n_steps steps in dimension n writes."""
    return Record(np.empty((n_steps + 1 if keep_all else 1, n)), np.zeros(max(n_steps, 1), np.int64),
                  np.zeros(max(n_steps, 1), np.int64), bool(keep_all))


class Setup(NamedTuple):
    """A run made ready: the provider, its data, the substeps' coefficients and the solver."""

    provider: object
    data: object
    gammas: np.ndarray
    solver: Solver


def setup(system, tableau, gammas=(1.0,), *, provider=None, tol: float | None = None,
          max_iter: int | None = None, options: dict | None = None) -> Setup:
    """The provider (default: `choose`'s for the system and `tableau`), its data for the
    substeps `gammas` (built with the provider's `options`) and the solver (tolerance: the
    provider's by default)."""
    g = check_gammas(gammas)
    provider = choose(system, tableau).provider if provider is None else provider
    tol = provider.tolerance if tol is None else float(tol)
    max_iter = NEWTON_MAX_ITERATIONS if max_iter is None else int(max_iter)
    return Setup(provider, provider.prepare(system, tableau, g.size, **(options or {})), g,
                 Solver(tol, max_iter, system.domain_code))


def check_processor(processor, gammas: np.ndarray) -> int:
    """The processor's number of substeps if the coefficients hold it twice and a kernel besides
    (InputError otherwise)."""
    if isinstance(processor, bool) or not isinstance(processor, (int, np.integer)) \
            or not (0 <= processor and 2 * processor < gammas.size):
        raise InputError(f"processor must be a number of substeps from 0 to {(gammas.size - 1) // 2}")
    return int(processor)


def run(system, tableau, h, n_steps, x0=None, *, gammas=(1.0,), processor: int = 0, span: float | None = None,
        provider=None, keep_all: bool = True, tol: float | None = None, max_iter: int | None = None,
        options: dict | None = None, name: str | None = None, extra: dict | None = None) -> Trajectory:
    """Integrate `system` by n_steps steps of size h (negative: backwards) of the composition of
    substeps gammas[0] h, gammas[1] h, ... of the RKHP method of `tableau` (gammas = (1,): the
    method itself; with `processor` > 0, gammas holds a processed composition's processor, kernel
    and inverse processor, `drive`), from x0 (default: the system's start), by `provider` (default: `choose`'s,
    its data built with `options`).

    A step advances the time by h span (default span: the sum of the gammas; a consistent
    composition passes 1, so that t_n = n h). Returns a Trajectory: states y_0..y_k with
    `keep_all`, else y_0 and the last state; Newton iterations and stage sweeps per step (all its
    substeps); a failed run keeps the states before the failing step and names it (with
    `keep_all`, a run that diverged ends before the state that diverged: `trajectory.checked`).
    The first call compiles (or loads numba's cache): its seconds are `compile_seconds`, apart
    from the run's. `extra` is added to what the trajectory reports of the run.
    """
    h, n_steps = check_step(h, n_steps, system.dim)
    ready = setup(system, tableau, gammas, provider=provider, tol=tol, max_iter=max_iter, options=options)
    y0 = system.start(x0)
    n = system.dim
    args = (ready.gammas, check_processor(processor, ready.gammas), h)
    t0 = time.perf_counter()
    drive(y0, *args, 0, ready.data, ready.solver, record(0, n, True))
    compile_seconds = time.perf_counter() - t0
    out = record(n_steps, n, keep_all)
    t0 = time.perf_counter()
    done, cause = drive(y0, *args, n_steps, ready.data, ready.solver, out)
    run_seconds = time.perf_counter() - t0
    cause = Failure(cause)
    failed = cause != Failure.OK
    step = h * (math.fsum(ready.gammas) if span is None else span)
    if keep_all:
        kept, times = out.states[: done + 1], step * np.arange(done + 1)
    else:
        kept, times = np.vstack([y0, out.states[0]]), np.array([0.0, step * done])
    details = {"substep": ready.provider.name, "newton_tolerance": ready.solver.tol,
               "newton_max_iterations": ready.solver.max_iter, "realisation": system.realisation,
               **ready.provider.extra(ready.data), **(extra or {})}
    trajectory = Trajectory(
        times=times, states=kept, newton_iterations=out.iterations[: done + failed],
        stage_sweeps=out.sweeps[: done + failed], cause=cause,
        status=failure_status(cause, done, step, system.domain) if failed else "ok",
        failed_step=done if failed else None, compile_seconds=compile_seconds,
        run_seconds=run_seconds, method=name or getattr(tableau, "name", "custom"), system=system.name,
        extra=details, poisson=system)
    return checked(trajectory, system) if keep_all else trajectory


def run_ensemble(system, tableau, h, n_steps, x0s, *, gammas=(1.0,), processor: int = 0, provider=None,
                 tol: float | None = None, max_iter: int | None = None, options: dict | None = None,
                 threads: int | None = None, executor=None) -> np.ndarray:
    """Final states of many trajectories at once (shape (m, n)), the arguments as `run`'s, in
    `threads` threads (default: the CPUs available) running the compiled loop without the GIL; with an `executor`
    (rkhp.base.executors), the starts are cut into one chunk per slot and each chunk runs so on a
    worker (the same final states: each trajectory is computed on its own). NumericalFailure
    naming the first failing trajectory if any fails."""
    h, n_steps = check_step(h, n_steps)
    x0s = np.ascontiguousarray(x0s, dtype=np.float64)
    if x0s.ndim != 2 or x0s.shape[1] != system.dim:
        raise InputError(f"initial conditions must have shape (m, {system.dim}), got {x0s.shape}")
    for i, x in enumerate(x0s):
        if not system.in_domain(x):
            raise InputError(f"initial condition {i} = {x.tolist()} is outside the domain")
    check_processor(processor, check_gammas(gammas))
    settings = (gammas, processor, None if provider is None else provider.name, tol, max_iter, options, threads)
    if executor is None:
        finals, done, causes = _ensemble_chunk(system, tableau, h, n_steps, x0s, *settings)
    else:
        chunks = np.array_split(x0s, max(1, min(len(x0s), executor.slots)))
        parts = run_all(executor, _ensemble_chunk, [(system, tableau, h, n_steps, c, *settings) for c in chunks])
        finals, done, causes = (np.concatenate([p[k] for p in parts]) for k in range(3))
    bad = np.flatnonzero(causes)
    if bad.size:
        i = int(bad[0])
        raise NumericalFailure(f"trajectory {i} of {len(x0s)}: "
                               + failure_status(Failure(causes[i]), int(done[i]), h, system.domain))
    return finals


def _ensemble_chunk(system, tableau, h, n_steps, x0s, gammas, processor, provider, tol, max_iter, options, threads):
    """(final states, steps done, Failure codes) of the trajectories from ``x0s``, in threads, each
    thread with data of its own; `provider` by name (a task of a pool: its arguments are sent)."""
    provider = None if provider is None else PROVIDERS[provider]
    m = len(x0s)
    finals = np.zeros_like(x0s)
    done = np.zeros(m, dtype=np.int64)
    codes = np.zeros(m, dtype=np.int64)
    threads = threads or available_cores()
    bounds = np.linspace(0, m, min(threads, max(m, 1)) + 1).astype(int)

    def batch(lo, hi):
        ready = setup(system, tableau, gammas, provider=provider, tol=tol, max_iter=max_iter, options=options)
        out = record(n_steps, system.dim, False)
        for t in range(lo, hi):
            done[t], codes[t] = drive(x0s[t], ready.gammas, processor, h, n_steps, ready.data, ready.solver, out)
            finals[t] = out.states[0]

    with ThreadPoolExecutor(max_workers=len(bounds) - 1) as pool:
        list(pool.map(batch, bounds[:-1], bounds[1:]))
    return finals, done, codes


def _direct(provider, system, gammas, h, n_steps, x0, keep_all, tol, max_iter, name):
    """RKHP Euler's substeps gammas h by the direct form `provider` (see `run`)."""
    from ..tableaux.files import load_tableau

    g = check_gammas(gammas)
    return run(system, load_tableau("euler"), h, n_steps, x0, gammas=g, provider=provider,
               keep_all=keep_all, tol=tol, max_iter=max_iter,
               name=name if g.size == 1 else f"{name}-composition", extra={"gammas": g.tolist()})


def integrate_closed_euler(system, gammas, h, n_steps, x0=None, keep_all: bool = True, *,
                           tol: float | None = None, max_iter: int | None = None) -> Trajectory:
    """Integrate `system` (family constant, lie-poisson or log-canonical, symmetric realisation) by
    n_steps steps of the composition of RKHP Euler steps gammas[0] h, gammas[1] h, ... (in that
    order), each in direct form (`rkhp.integrators.closed_euler`); h may be negative; gammas = (1,)
    is RKHP Euler. Returns `run`'s Trajectory (a step advances the time by h sum(gammas)).
    InputError for another family or realisation, or bad arguments."""
    return _direct(CLOSED, system, gammas, h, n_steps, x0, keep_all, tol, max_iter, "closed-euler")


def integrate_spray_euler(system, gammas, h, n_steps, x0=None, keep_all: bool = True, *,
                          tol: float | None = None, max_iter: int | None = None) -> Trajectory:
    """`integrate_closed_euler` on the full Poisson-spray realisation (family general, realisation
    symmetric) by its direct form (`rkhp.integrators.spray_euler`)."""
    return _direct(SPRAY, system, gammas, h, n_steps, x0, keep_all, tol, max_iter, "spray-euler")
