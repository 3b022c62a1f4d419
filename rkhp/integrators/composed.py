"""Compositions of RKHP steps as one compiled loop (docs/compositions.md, docs/theory.md §12).

A step of size h of the composition is the base RKHP step (`engine.rkhp_step`) taken with the
substeps gamma_1 h, ..., gamma_s h in turn, whole in compiled code. Each substep keeps its own
history of psi (the start predictor of `rkhp_step` extrapolates psi over the previous steps of the
same size): substep i of step k starts from the psi of substep i of steps k-1, k-2, k-3, so a
negative substep is never predicted from a positive one.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from ..base.bounds import check_step
from ..base.errors import InputError
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from .engine import (
    MEMO_HISTORY,
    MEMO_NEWTON_L,
    Method,
    Record,
    Solver,
    interpreted,
    rkhp_step,
    state_failure,
    step_buffers,
)
from .failure import Failure, failure_status
from .newton import NEWTON_MAX_ITERATIONS, NEWTON_TOLERANCE
from .rkhp_method import (
    engine_data,
    is_implicit,
    resolve_tableau,
    stage_solve,
    tableau_arrays,
)
from .trajectory import Trajectory, checked


class Substeps(NamedTuple):
    """The method of a composed step: the base tableau (A, b) and the substep sizes gamma_i h."""

    A: np.ndarray
    b: np.ndarray
    sizes: np.ndarray


class SubstepMemory(NamedTuple):
    """Per substep i: psi of its three previous steps (hist[i], shape (3, n)) and how many there
    are (count[i])."""

    hist: np.ndarray
    count: np.ndarray


def substep_memory(substeps: int, n: int) -> SubstepMemory:
    return SubstepMemory(np.zeros((substeps, 3, n)), np.zeros(substeps))


@nb.njit(inline="always", **NJIT_NORC)
def _swap_history(buf, memory, i, n, into_buffers):
    """Load substep i's psi history into the step buffers (or store it back)."""
    for r in range(3):
        for k in range(n):
            if into_buffers:
                buf.hist[r, k] = memory.hist[i, r, k]
            else:
                memory.hist[i, r, k] = buf.hist[r, k]
    if into_buffers:
        buf.memo[MEMO_HISTORY] = memory.count[i]
    else:
        memory.count[i] = buf.memo[MEMO_HISTORY]


@nb.njit(**NJIT_NORC)
def composed_run(y0, method, n_steps, run, tapes, space, buf, memory, solver, record):
    """Integrate n_steps composed steps from y0 (the explicit base tableau of `method`), the
    tapes evaluated by the interpreter of their class at the address `run`; returns (number of completed steps,
    Failure of the step after them or Failure.OK)."""
    program = interpreted(tapes, run, space, buf.work)
    n = y0.shape[0]
    y = buf.y
    for k in range(n):
        y[k] = y0[k]
        record.states[0, k] = y0[k]
    buf.memo[MEMO_NEWTON_L] = 0.0
    for i in range(method.sizes.shape[0]):
        memory.count[i] = 0.0
    for step in range(n_steps):
        total = 0
        for i in range(method.sizes.shape[0]):
            _swap_history(buf, memory, i, n, True)
            cause, it, _ = rkhp_step(Method(method.A, method.b, method.sizes[i]), program, space, buf,
                                     solver, None)
            _swap_history(buf, memory, i, n, False)
            total += it
            if cause == Failure.OK:
                cause = state_failure(buf.y_next, solver.domain)
            if cause != Failure.OK:
                record.iterations[step] = total
                return step, cause
            for k in range(n):
                y[k] = buf.y_next[k]
        record.iterations[step] = total
        row = step + 1 if record.keep_all else 0
        for k in range(n):
            record.states[row, k] = y[k]
    return n_steps, Failure.OK


def integrate_composition(system, composition, h, n_steps, x0=None, *, keep_all: bool = True,
                          tol: float | None = None, max_iter: int | None = None):
    """Integrate `system` with a :class:`~rkhp.tableaux.compositions.Composition` of an explicit
    RKHP base method: n_steps steps of size h (negative h runs backwards). Returns a Trajectory
    whose Newton iterations are summed over the substeps of each step."""
    base = resolve_tableau(composition.base)
    h, n_steps = check_step(h, n_steps, system.dim)
    A, b = tableau_arrays(base)
    if is_implicit(A):
        raise InputError(f"{composition.name}: the base method {base.name} is implicit; compositions "
                         "run explicit RKHP bases")
    tol = NEWTON_TOLERANCE if tol is None else float(tol)
    max_iter = NEWTON_MAX_ITERATIONS if max_iter is None else int(max_iter)
    y0 = system.start(x0)
    tapes, interpreter, space = engine_data(system, len(b), stage_solve(base, A))
    buf = step_buffers(tapes, system.dim, len(b), space)
    method = Substeps(A, b, h * np.asarray(composition.gamma_float, dtype=np.float64))
    memory = substep_memory(composition.substeps, system.dim)
    solver = Solver(tol, max_iter, system.domain_code)
    t0 = time.perf_counter()
    run = interpreter.address
    composed_run(y0, method, 0, run, tapes, space, buf, memory, solver,
                 Record(np.zeros((1, y0.size)), np.zeros(1, np.int64), True))
    compile_seconds = time.perf_counter() - t0
    rows = n_steps + 1 if keep_all else 1
    record = Record(np.empty((rows, y0.size)), np.zeros(max(n_steps, 1), np.int64), keep_all)
    t0 = time.perf_counter()
    done, cause = composed_run(y0, method, n_steps, run, tapes, space, buf, memory, solver, record)
    run_seconds = time.perf_counter() - t0
    failed = cause != Failure.OK
    states = record.states[: done + 1] if keep_all else record.states[:1]
    return checked(Trajectory(
        times=h * np.arange(done + 1) if keep_all else np.array([h * done]), states=states,
        newton_iterations=record.iterations[: done + failed], stage_sweeps=np.zeros(done + failed, np.int64),
        cause=Failure(cause), status=failure_status(Failure(cause), done, h, system.domain) if failed else "ok",
        failed_step=done if failed else None, compile_seconds=compile_seconds, run_seconds=run_seconds,
        method=composition.name, system=system.name,
        extra={"newton_tolerance": tol, "newton_max_iterations": max_iter,
               "realisation": system.realisation, "base": base.name,
               "substeps": composition.substeps}, poisson=system), system)
