"""The one driver of the RKHP integrators: the step loop over substeps gamma_1 h, ..., gamma_s h of a
base method, whatever provider computes them (docs/engine.md "One driver, many substeps",
docs/theory.md §12).

A step of size h is the substeps gamma_1 h, ..., gamma_s h in turn (a tableau alone: s = 1,
gamma = (1)); a processed composition P^-1 o K^n o P (docs/theory.md §12) has its processor's
substeps first in the coefficients and its inverse's last: those run once before the first step
and once at each state the run keeps (its output), not at every step. Each substep is computed by
the substep provider that `rkhp.integrators.substeps.choose` picks for the system and the base
method. `drive` is the compiled loop, written once: numba compiles it
once per provider (the class of the provider's data); it records the states, the Newton (or chord)
iterations and the stage sweeps of each step, summed over its substeps, and checks the state after
every substep (`rkhp.integrators.engine_state.state_failure`: finite, in the system's domain). `run`
is its Python entry (a :class:`~rkhp.integrators.trajectory.Trajectory`), `run_ensemble` runs many
initial values (threads over the compiled loop, which releases the GIL); `integrate_closed_euler`
and `integrate_spray_euler` run RKHP Euler and its compositions by a direct form,
`integrate_taylor` the Taylor Hamiltonian Poisson integrators (`rkhp.integrators.taylor`).
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
from .engine_state import Solver, state_failure
from .failure import Failure, failure_status
from .newton import NEWTON_MAX_ITERATIONS
from .prepared import Lender, Lent
from .substeps import CLOSED, PROVIDERS, SPRAY, THP, begin, choose, resume, substep
from .taylor import thp_method
from .trajectory import GROWTH, Trajectory, checked


class Record(NamedTuple):
    """Where a run writes: states (n_steps + 1, n) when every state is kept (states[k] = y_k), else
    (1, n) (the last state); per step, its Newton iterations and its stage sweeps (summed over its
    substeps); whether every state is kept; peak (2,): the largest |component| of y_0 and of
    every state recorded (what `trajectory.divergence` looks at first)."""

    states: np.ndarray
    iterations: np.ndarray
    sweeps: np.ndarray
    keep_all: bool
    peak: np.ndarray


@nb.njit(**NJIT_NORC)
def drive(y0, gammas, processor, h, n_steps, data, solver, record):
    """n_steps steps of size h from y0 of the provider whose data is `data`
    (`rkhp.integrators.substeps`), substep i of a step warm-started from substep i of the steps
    before (the provider's memory, emptied by its ``begin``); the state is checked after every
    substep. Without a processor (`processor` = 0) a step is the substeps gammas[0] h,
    gammas[1] h, ...; with one, gammas holds the processor's `processor` coefficients, the
    kernel's and the inverse processor's (`rkhp.tableaux.compositions.one_step`): the processor's
    substeps (of size gammas[i] |h|) run once from y0, each step is the kernel's, and the inverse
    processor's run from each state kept (every state with `record.keep_all`, else the last),
    each of its substeps warm-started from its runs from the states before (`resume`).
    Returns (completed steps, the code of the Failure of the step after them or 0, Failure.OK)."""
    context = begin(data, y0)
    n = y0.shape[0]
    peak = 0.0
    for k in range(n):
        record.states[0, k] = y0[k]
        peak = max(peak, abs(y0[k]))
    record.peak[0] = peak
    record.peak[1] = peak
    end = gammas.shape[0]
    cause, it, done = _substeps(data, context, gammas, 0, processor, abs(h), solver)
    if cause != Failure.OK:
        record.iterations[0] = it
        record.sweeps[0] = done
        return 0, _code(cause)
    steps, cause = _steps(data, context, gammas, processor, end - processor, h, n_steps, solver, record)
    record.iterations[0] += it
    record.sweeps[0] += done
    if processor == 0:
        return steps, _code(cause)
    first = 0 if not record.keep_all and steps > 0 else 1
    rows = steps + 1 if record.keep_all else 1
    for row in range(first, rows):
        resume(data, record.states[row])
        failed, it, done = _substeps(data, context, gammas, end - processor, end, abs(h), solver)
        if failed != Failure.OK:  # the output of this row failed: the run ends before it
            if not record.keep_all:
                for k in range(n):
                    record.states[0, k] = y0[k]
            return (row - 1 if record.keep_all else 0), _code(failed)
        at = row - 1 if record.keep_all else steps - 1
        record.iterations[at] += it
        record.sweeps[at] += done
        for k in range(n):
            record.states[row, k] = data.y[k]
            record.peak[1] = max(record.peak[1], abs(data.y[k]))
    return steps, _code(cause)


@nb.njit(inline="always", **NJIT_NORC)
def _code(cause):
    """A Failure's integer code: Python receives a plain int, where a Failure member would be
    boxed (the enum class unpickled) on every call."""
    return cause + 0


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
    """n_steps steps, each the substeps lo .. hi - 1 of sizes gammas[i] h, the states recorded
    (and the largest |component| in `record.peak`); returns (completed steps, Failure of the step
    after them or Failure.OK)."""
    y = data.y
    n = y.shape[0]
    peak = record.peak[1]
    for step in range(n_steps):
        cause, iterations, sweeps = _substeps(data, context, gammas, lo, hi, h, solver)
        record.iterations[step] = iterations
        record.sweeps[step] = sweeps
        if cause != Failure.OK:
            return step, cause
        row = step + 1 if record.keep_all else 0
        for k in range(n):
            record.states[row, k] = y[k]
            peak = max(peak, abs(y[k]))
        record.peak[1] = peak
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
                  np.zeros(max(n_steps, 1), np.int64), bool(keep_all), np.zeros(2))


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


PREPARED = Lender()
"""The prepared runs of this process (`rkhp.integrators.prepared`): a provider's data is built
once per system, base method, number of substeps, provider, solver settings and options, then
lent to one run at a time."""

ONE = check_gammas((1.0,))
"""The substeps of a method of one step (a tableau alone)."""


class Ready(NamedTuple):
    """A Setup lent to runs, and the compiled loop to call with its arguments: `drive`'s entry
    point for their types once a run has compiled it (`compiled_loop`), `drive` itself before."""

    setup: Setup
    loop: object


def compiled_loop(args) -> object:
    """The entry point of `drive` compiled for the types of `args` (a call that `drive` has made):
    called directly, it skips the dispatcher's resolution of the types (about 6 us of a call);
    the arguments of every later call must have the same types (arrays C-contiguous, of the same
    dtype and dimensions; `Record`s of the same shape of fields). `drive` itself where numba
    keeps no such entry."""
    overload = drive.overloads.get(tuple(drive.typeof_pyval(a) for a in args))
    return drive if overload is None else overload.entry_point


def _take(system, tableau, g, provider, tol, max_iter, options) -> Lent:
    """A Setup lent for a run of `g.size` substeps (see `setup`); its gammas are those it was
    built for, the run passes its own."""
    key = (g.size, None if provider is None else provider.name, tol, max_iter,
           None if not options else tuple(sorted(options.items())))
    return PREPARED.take(system, tableau, key, lambda: Ready(setup(system, tableau, g, provider=provider, tol=tol,
                                                                   max_iter=max_iter, options=options), drive))


def _warm(lent: Lent, y0, gammas, processor: int, h) -> tuple[Lent, float]:
    """A lent Ready whose loop is compiled (a run of 0 steps, on data built for this run: the
    first compiles or loads numba's cache) and its compile seconds (0 for data run before)."""
    if not lent.built:
        return lent, 0.0
    ready = lent.item.setup
    args = (y0, gammas, processor, h, 0, ready.data, ready.solver, record(0, y0.shape[0], True))
    t0 = time.perf_counter()
    drive(*args)
    seconds = time.perf_counter() - t0
    return lent._replace(item=Ready(ready, compiled_loop(args))), seconds


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
    and inverse processor, `drive`), from x0 (default: the system's start), by `provider`
    (default: `choose`'s, its data built with `options`; built once and lent to this run,
    `PREPARED`).

    A step advances the time by h span (default span: the sum of the gammas; a consistent
    composition passes 1, so that t_n = n h). Returns a Trajectory: states y_0..y_k with
    `keep_all`, else y_0 and the last state; Newton iterations and stage sweeps per step (all its
    substeps); a failed run keeps the states before the failing step and names it (with
    `keep_all`, a run that diverged ends before the state that diverged: `trajectory.checked`).
    The first run of prepared data compiles the loop (or loads numba's cache): its seconds are
    `compile_seconds`, apart from the run's (0 for data prepared before). `extra` is added to
    what the trajectory reports of the run.
    """
    g = check_gammas(gammas)
    return run_checked(system, tableau, h, n_steps, x0, g, math.fsum(g) if span is None else float(span),
                       processor=check_processor(processor, g), provider=provider, keep_all=keep_all, tol=tol,
                       max_iter=max_iter, options=options, name=name, extra=extra)


def run_checked(system, tableau, h, n_steps, x0, gammas: np.ndarray, span: float, *, processor: int = 0,
                provider=None, keep_all: bool = True, tol: float | None = None, max_iter: int | None = None,
                options: dict | None = None, name: str | None = None, extra: dict | None = None) -> Trajectory:
    """`run` with the substeps' coefficients and the processor's length already checked (an array
    from `check_gammas`, never changed; `check_processor`) and the span given: what a resolved
    method calls (`rkhp.integrators.methods`)."""
    h, n_steps = check_step(h, n_steps, system.dim)
    y0 = system.start(x0)
    lent = _take(system, tableau, gammas, provider, tol, max_iter, options)
    try:
        lent, compile_seconds = _warm(lent, y0, gammas, processor, h)
        ready, loop = lent.item
        out = record(n_steps, y0.shape[0], keep_all)
        t0 = time.perf_counter()
        done, code = loop(y0, gammas, processor, h, n_steps, ready.data, ready.solver, out)
        run_seconds = time.perf_counter() - t0
        details = {"substep": ready.provider.name, "newton_tolerance": ready.solver.tol,
                   "newton_max_iterations": ready.solver.max_iter, "realisation": system.realisation,
                   **ready.provider.extra(ready.data)}
    finally:
        PREPARED.give(lent)
    if extra:
        details.update(extra)
    failed = code != 0
    cause = Failure(code) if failed else Failure.OK
    step = h * span
    if keep_all:
        kept, times = out.states[: done + 1], step * np.arange(done + 1)
    else:
        kept, times = np.empty((2, y0.shape[0])), np.array([0.0, step * done])
        kept[0], kept[1] = y0, out.states[0]
    trajectory = Trajectory(
        times=times, states=kept, newton_iterations=out.iterations[: done + failed],
        stage_sweeps=out.sweeps[: done + failed], cause=cause,
        status=failure_status(cause, done, step, system.domain) if failed else "ok",
        failed_step=done if failed else None, compile_seconds=compile_seconds,
        run_seconds=run_seconds, method=name or getattr(tableau, "name", "custom"), system=system.name,
        extra=details, poisson=system)
    grown = keep_all and not out.peak[1] <= GROWTH * max(1.0, out.peak[0])
    return checked(trajectory, system) if grown else trajectory


class Ensemble(NamedTuple):
    """The runs of an ensemble, one row per trajectory: its final state (the last state it
    reached, for a failed run the state before the failing step), the steps it completed and its
    Failure code."""

    finals: np.ndarray
    done: np.ndarray
    causes: np.ndarray


def ensemble_plan(system, h, n_steps, x0s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The starts (m, n), step sizes (m,) and numbers of steps (m,) of an ensemble, checked: h
    and n_steps are one value for every start or one per start (`check_step` each); every start
    in the system's domain. InputError otherwise."""
    x0s = np.array(x0s, dtype=np.float64)  # a copy: C-contiguous and writable, as the compiled loop takes it
    if x0s.ndim != 2 or x0s.shape[1] != system.dim:
        raise InputError(f"initial conditions must have shape (m, {system.dim}), got {x0s.shape}")
    m = len(x0s)
    hs, counts = (np.broadcast_to(np.asarray(v, dtype=object), (m,)) if np.ndim(v) == 0 or len(v) == m
                  else None for v in (h, n_steps))
    if hs is None or counts is None:
        raise InputError(f"the step sizes and the numbers of steps must be one value or one per start ({m})")
    steps = [check_step(hh, nn) for hh, nn in zip(hs, counts, strict=True)]
    for i, x in enumerate(x0s):
        if not system.in_domain(x):
            raise InputError(f"initial condition {i} = {x.tolist()} is outside the domain")
    return (x0s, np.array([s[0] for s in steps], dtype=np.float64).reshape(m),
            np.array([s[1] for s in steps], dtype=np.int64).reshape(m))


def run_ensemble(system, tableau, h, n_steps, x0s, *, gammas=(1.0,), processor: int = 0, provider=None,
                 tol: float | None = None, max_iter: int | None = None, options: dict | None = None,
                 threads: int | None = None, executor=None) -> np.ndarray:
    """Final states of many trajectories at once (shape (m, n)), the arguments as `run`'s, h and
    n_steps one value or one per start (`ensemble_plan`), in `threads` threads (default: the CPUs
    available) running the compiled loop without the GIL, each thread with prepared data of its
    own; with an `executor` (rkhp.base.executors), the starts are cut into one chunk per slot and
    each chunk runs so on a worker. Each trajectory is computed on its own, as `run` computes it:
    the final states are those of one run at a time, bit for bit. NumericalFailure naming the
    first failing trajectory if any fails."""
    result = ensemble_runs(system, tableau, h, n_steps, x0s, gammas=gammas, processor=processor, provider=provider,
                           tol=tol, max_iter=max_iter, options=options, threads=threads, executor=executor)
    bad = np.flatnonzero(result.causes)
    if bad.size:
        i = int(bad[0])
        step = float(np.broadcast_to(h, (len(result.causes),))[i]) * math.fsum(check_gammas(gammas))
        raise NumericalFailure(f"trajectory {i} of {len(result.causes)}: "
                               + failure_status(Failure(result.causes[i]), int(result.done[i]), step,
                                                system.domain))
    return result.finals


def ensemble_runs(system, tableau, h, n_steps, x0s, *, gammas=(1.0,), processor: int = 0, provider=None,
                  tol: float | None = None, max_iter: int | None = None, options: dict | None = None,
                  threads: int | None = None, executor=None) -> Ensemble:
    """`run_ensemble`'s runs, failed ones included (an `Ensemble`)."""
    x0s, hs, counts = ensemble_plan(system, h, n_steps, x0s)
    g = check_gammas(gammas)
    settings = (g, check_processor(processor, g), None if provider is None else provider.name, tol, max_iter,
                options, threads)
    if executor is None:
        return Ensemble(*_ensemble_chunk(system, tableau, hs, counts, x0s, *settings))
    cuts = np.array_split(np.arange(len(x0s)), max(1, min(len(x0s), executor.slots)))
    parts = run_all(executor, _ensemble_chunk,
                    [(system, tableau, hs[c], counts[c], x0s[c], *settings) for c in cuts])
    return Ensemble(*(np.concatenate([p[k] for p in parts]) for k in range(3)))


def _ensemble_chunk(system, tableau, hs, counts, x0s, g, processor, provider, tol, max_iter, options, threads):
    """(final states, steps done, Failure codes) of the trajectories from ``x0s`` (step sizes
    ``hs``, numbers of steps ``counts``), in threads, each thread with prepared data of its own;
    `provider` by name (a task of a pool: its arguments are sent)."""
    provider = None if provider is None else PROVIDERS[provider]
    m = len(x0s)
    finals = np.zeros_like(x0s)
    done = np.zeros(m, dtype=np.int64)
    codes = np.zeros(m, dtype=np.int64)
    threads = threads or available_cores()
    bounds = np.linspace(0, m, min(threads, max(m, 1)) + 1).astype(int)

    def batch(lo, hi):
        if lo == hi:
            return
        lent = _take(system, tableau, g, provider, tol, max_iter, options)
        try:
            lent, _ = _warm(lent, x0s[lo], g, processor, float(hs[lo]))
            ready, loop = lent.item
            out = record(int(counts[lo:hi].max(initial=0)), system.dim, False)
            for t in range(lo, hi):
                done[t], codes[t] = loop(x0s[t], g, processor, float(hs[t]), int(counts[t]), ready.data, ready.solver,
                                         out)
                finals[t] = out.states[0]
        finally:
            PREPARED.give(lent)

    if len(bounds) == 2:
        batch(0, m)
    else:
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


def integrate_taylor(system, order: int, degenerate: bool, h, n_steps, x0=None, keep_all: bool = True, *,
                     tol: float | None = None, max_iter: int | None = None) -> Trajectory:
    """Integrate `system` by n_steps steps of the THP of order `order` (1 to 8) over T_0
    (`degenerate`) or T (paper Thm 5.1), its steps by the provider ``thp``
    (`rkhp.integrators.taylor`). Returns `run`'s Trajectory; InputError for bad arguments."""
    method = thp_method(order, degenerate)
    return run(system, method, h, n_steps, x0, provider=THP, keep_all=keep_all, tol=tol, max_iter=max_iter,
               name=method.name)
