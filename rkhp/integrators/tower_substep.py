"""The RKHP step of the Taylor tower (`rkhp.integrators.engine.rkhp_step`, paper §5.2, docs/theory.md
§5, §7, §10) as a substep provider of the driver (`rkhp.integrators.driver`): any tableau,
explicit or implicit, on any system.

A composition's substep i keeps its own history of psi (the start predictor of `rkhp_step`
extrapolates psi over the previous steps of the same size): substep i of step k starts from the
psi of substep i of steps k-1, k-2, k-3, so a negative substep is never predicted from a positive
one. A method of one step is the composition of one substep of size h.

Compiled data: `TowerSubstep` (the tableau, the tapes and their interpreter's address, the jet
space, the step buffers, the substeps' memory, the stage solve, the state); `begin` (inlined into
the driver's loop: the addresses of the tapes are taken on its stack) and the substeps are the
provider's compiled functions (`rkhp.integrators.substeps`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import as_plain, interpreter
from ..taylor.jets import jet_space
from .engine import rkhp_step
from .engine_state import (
    MEMO_HISTORY,
    EngineData,
    StageSolve,
    StepTableau,
    SystemTapes,
    interpreted,
    step_buffers,
)
from .failure import Failure
from .newton import NEWTON_TOLERANCE, STAGE_MAX_SWEEPS

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


SETUP_SECONDS = 4e-9
"""CPU seconds per (product term x monomial) to build a jet space's tables (`rkhp.taylor.jets`):
3.8e-9 measured for 24 variables at degree 4, 2.9e-9 for 12 at degree 5 (2026-12-06)."""
STEP_SECONDS = 1.1e-7
"""CPU seconds per (product term x stage) of one tower step: 1.07e-7 measured for
paper-three-stage on toda:12 (12 variables, degree 4), 6.8e-8 on toda:6 (2026-12-06)."""


class TowerCost(NamedTuple):
    """What the tower's jets cost on a system (`tower_cost`): their degree, the product terms of
    their multiplication table (monomials of that degree in 2n variables), the monomials (in n),
    and the estimated CPU seconds of building the tables and of one step of `substeps`
    substeps."""

    degree: int
    pairs: int
    size: int
    setup_seconds: float
    step_seconds: float

    def seconds(self, steps: int) -> float:
        """Estimated CPU seconds of a run of `steps` steps, the tables built first."""
        return self.setup_seconds + steps * self.step_seconds


def tower_cost(system, tableau, substeps: int = 1) -> TowerCost:
    """The cost of the tower's steps of `tableau` on `system`, estimated without building
    anything: jets of degree D = s + 1 (explicit; an implicit tableau: `implicit_degree`) in n
    variables have C(n + D, D) monomials and C(2n + D, D) product terms (pairs of monomials whose
    degrees sum to at most D), and the work grows with both (SETUP_SECONDS, STEP_SECONDS)."""
    tableau = resolve_tableau(tableau)
    A, b = tableau_arrays(tableau)
    degree = stage_solve(tableau, A).degree or len(b) + 1
    n = system.dim
    pairs, size = math.comb(2 * n + degree, degree), math.comb(n + degree, degree)
    return TowerCost(degree, pairs, size, SETUP_SECONDS * pairs * size,
                     STEP_SECONDS * pairs * len(b) * substeps)


def engine_data(system, stages: int, stage):
    """`rkhp.integrators.engine_state.EngineData`: the tapes, interpreter and jet space for the
    compiled engine, jets in n variables of degree s + 1 (explicit) or the stage degree
    (implicit)."""
    degree = stage.degree if stage.degree > 0 else stages + 1
    space = jet_space(system.dim, degree)
    if len(space.pa) > MAX_PRODUCT_PAIRS:
        raise InputError(f"the method needs Taylor polynomials of degree {degree} in "
                         f"{system.dim} variables ({len(space.pa)} product terms): too large")
    plain = [as_plain(t) for t in (system.f_tape, system.h_tape, system.alpha_tape, system.beta_tape)]
    return EngineData(SystemTapes(*plain), interpreter(system.f_tape), space)


class PsiHistory(NamedTuple):
    """Per substep i: psi of its three previous steps (hist[i], shape (3, n)) and how many there
    are (count[i])."""

    hist: np.ndarray
    count: np.ndarray


class TowerSubstep(NamedTuple):
    """What the tower's substeps of one run use: the tableau's A (s, s) and b (s,); the system's
    plain tapes, the address of their class's interpreter and the jet space
    (`engine_data`); the step buffers (`engine_state.step_buffers`: the
    state is buf.y); the memory of the composition's substeps; the stage solve (None for an
    explicit tableau, so that numba compiles its substep without the implicit tower: docs/engine.md
    "Compile time"; a `rkhp.integrators.engine_state.StageSolve` for an implicit one); the state the
    substeps advance, y (buf.y)."""

    A: np.ndarray
    b: np.ndarray
    tapes: SystemTapes
    run: int
    space: object
    buf: object
    memory: PsiHistory
    stage: StageSolve | None
    y: np.ndarray


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


@nb.njit(inline="always", **NJIT_NORC)
def resume(data, y0):
    """The state set to y0 (buf.y), every substep's history and every scalar the steps keep
    (buf.memo) kept."""
    buf = data.buf
    for k in range(y0.shape[0]):
        buf.y[k] = y0[k]


@nb.njit(inline="always", **NJIT_NORC)
def begin(data, y0):
    """Start a run at y0 (`resume`), every substep without history and every scalar the
    steps keep (buf.memo: history, Lipschitz estimate, factorisation, stage solve) as in new
    buffers, so that a run on data prepared before computes what it computes on new data;
    returns the tapes evaluated at their interpreter's address (`engine_state.interpreted`:
    copies on the stack of the loop this is inlined into)."""
    resume(data, y0)
    buf = data.buf
    for j in range(buf.memo.shape[0]):
        buf.memo[j] = 0.0
    for i in range(data.memory.count.shape[0]):
        data.memory.count[i] = 0.0
    return interpreted(data.tapes, data.run, data.space, buf.work)


@nb.njit(inline="always", **NJIT_NORC)
def explicit_substep(data, program, i, hs, solver):
    """Substep i of size hs of an explicit tableau from buf.y (into buf.y when it succeeds);
    returns (Failure, Newton iterations, stage sweeps)."""
    buf = data.buf
    n = buf.y.shape[0]
    _swap_history(buf, data.memory, i, n, True)
    cause, it, sweeps = rkhp_step(StepTableau(data.A, data.b, hs), program, data.space, buf, solver, None)
    _swap_history(buf, data.memory, i, n, False)
    if cause == Failure.OK:
        for k in range(n):
            buf.y[k] = buf.y_next[k]
    return cause, it, sweeps


@nb.njit(inline="always", **NJIT_NORC)
def implicit_substep(data, program, i, hs, solver):
    """`explicit_substep` for an implicit tableau (its stages solved as data.stage says)."""
    buf = data.buf
    n = buf.y.shape[0]
    _swap_history(buf, data.memory, i, n, True)
    cause, it, sweeps = rkhp_step(StepTableau(data.A, data.b, hs), program, data.space, buf, solver, data.stage)
    _swap_history(buf, data.memory, i, n, False)
    if cause == Failure.OK:
        for k in range(n):
            buf.y[k] = buf.y_next[k]
    return cause, it, sweeps


def tower_substep(system, tableau, substeps: int, stage_degree: int | None = None) -> TowerSubstep:
    """The data of `substeps` tower substeps of `tableau` on `system` (an implicit tableau's stage
    functions are jets of degree `stage_degree`, default `implicit_degree`)."""
    tableau = resolve_tableau(tableau)
    A, b = tableau_arrays(tableau)
    stage = stage_solve(tableau, A, stage_degree)
    tapes, interpreter, space = engine_data(system, len(b), stage)
    buf = step_buffers(tapes, system.dim, len(b), space, stage.degree)
    memory = PsiHistory(np.zeros((substeps, 3, system.dim)), np.zeros(substeps))
    return TowerSubstep(A, b, tapes, interpreter.address, space, buf, memory, compiled_stage(stage), buf.y)


def check_composable(tableau, name: str) -> None:
    """InputError unless `tableau` is explicit: compositions run explicit RKHP bases."""
    A, _ = tableau_arrays(tableau)
    if is_implicit(A):
        raise InputError(f"{name}: the base method {tableau.name} is implicit; compositions run "
                         "explicit RKHP bases")


def tower_extra(data: TowerSubstep) -> dict:
    """What a run reports of its tower substeps: the stage degree (0: explicit)."""
    return {"stage_degree": 0 if data.stage is None else data.stage.degree}


TOLERANCE = NEWTON_TOLERANCE
"""The default tolerance of the tower's Newton iteration (`rkhp.integrators.newton`)."""
