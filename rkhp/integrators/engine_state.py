"""The state of the RKHP step loop (docs/engine.md "The state of the step loop"): the compiled
data are small named groups, `SystemTapes` (the four tapes), `rkhp.taylor.jets.JetSpace`,
`StepTableau` (A, b, h), `Solver`, `StageSolve`, `StepBuffers` (every work array of the step
loop, allocated once by `step_buffers`; the scalars kept between towers and steps in the named
slots MEMO_HISTORY ... MEMO_STAGE_NEWTON_FAILS of its memo), and `Interpreted` (the tapes as the
loop evaluates them, `interpreted`). A run ends with a `rkhp.integrators.failure.Failure`;
`state_failure` is the one step validator (finite values, the system's domain) of every
integrator. The functions the notes below name are those of the step (`rkhp.integrators.engine`)
and of its towers (`rkhp.integrators.tower`, `rkhp.integrators.implicit_tower`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..systems.core import DOMAINS
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import Interpreter, TapeWork, address_of, tape_work
from ..taylor.jets import JetSpace
from ..taylor.tape import Tape
from .failure import Failure

POSITIVE_ORTHANT = DOMAINS["positive orthant"]


# The slots of StepBuffers.memo, the scalars that the step loop keeps from one tower or step to
# the next (module constants, which numba folds: the compiled code indexes by the number).
MEMO_HISTORY = 0
"""How many previous steps' psi buf.hist holds (0 to 3; the start predictor of `rkhp_step`)."""
MEMO_NEWTON_L = 1
"""Newton's quadratic constant L (|dx_{k+1}| ~ L |dx_k|^2) measured on an earlier step (0: unknown)."""
MEMO_RATE = 2
"""The implicit stages' rate h |c|_1 (`_stage_measure`, `_stage_weights`)."""
MEMO_FACTOR = 3
"""The implicit stages' effect factor (`_stage_measure`)."""
MEMO_EFFECT = 4
"""The stages' measure at the last sweep of this step; inf at the start of a step (`implicit_tower`)."""
MEMO_SHIFT_BEFORE = 5
"""The Taylor shifts (max-norm, summed) before the last sweep of every degree of G (`_stale_factor`)."""
MEMO_SHIFT_SINCE = 6
"""The Taylor shifts since the last sweep of every degree of G (`_stale_factor`)."""
MEMO_SWEEPS = 7
"""The sweeps of this step, from its first tower on (`implicit_tower`)."""
MEMO_STALLED = 8
"""1 once the sweeps have stalled in this run: every tower then solves the stages by `_stage_newton`."""
MEMO_JACOBIAN_KEPT = 9
"""1 while StepBuffers.stage_newton holds a factorised Jacobian (`_stage_newton`)."""
MEMO_STAGE_NEWTON_FAILS = 10
"""The `_stage_newton` solves of this step that found no solution (`implicit_tower`)."""
MEMO_FACTORED = 11
"""1 while StepBuffers.LU and perm hold the factors of StepBuffers.Jalpha, -1 while Jalpha is
singular, 0 when it changed since (`newton_solve`)."""
MEMO_SIZE = 12
"""The number of memo slots."""


class SystemTapes(NamedTuple):
    """The tapes of a system over the 2n inputs (x, p): f = H o alpha, H, alpha, beta (plain
    tapes: `rkhp.taylor.interpreter.as_plain`)."""

    f: Tape
    h: Tape
    alpha: Tape
    beta: Tape


class Interpreted(NamedTuple):
    """The tapes of `SystemTapes` and the address of their class's interpreter
    (`rkhp.taylor.interpreter.Interpreter.address`), as the step loop uses them, with the
    addresses of copies of the tapes, the jet space and the work arrays taken once for the run
    (`interpreted`): the tape f is evaluated as ``run_from(tapes.run, tapes.f_at, D,
    tapes.space_at, tapes.work_at)`` (`rkhp.taylor.interpreter.run_from`)."""

    f: Tape
    h: Tape
    alpha: Tape
    beta: Tape
    run: int
    f_at: object
    h_at: object
    alpha_at: object
    beta_at: object
    space_at: object
    work_at: object


class EngineData(NamedTuple):
    """What the compiled engine evaluates a system with: its tapes (plain), the interpreter of
    their class (compiled engine code takes its address) and the jet space
    (`rkhp.integrators.tower_substep.engine_data`)."""

    tapes: SystemTapes
    interpreter: Interpreter
    space: JetSpace


class StepBuffers(NamedTuple):
    """Every work array of the RKHP step loop (n: dimension, s: stages).

    work: the interpreter's; G (s, n, jet size): gradients of the stage functions; psi, Jpsi,
    alpha, Jalpha: the tower's results; x, delta, res (n): Newton's iterate, correction and
    residual; LU (n, n), perm (n,) int64, v (n): the linear solve's (`newton_solve`); hist (3, n):
    psi of the three previous steps; memo (MEMO_SIZE,): the scalars kept from one tower or step to
    the next, each in its named slot (MEMO_HISTORY ... MEMO_STAGE_NEWTON_FAILS); y, y_next (n): the
    state before and after the step; Gx (n): the point where G is expanded
    (implicit stages); changes (jet degree + 1,): per degree k of G, the weighted change of its
    coefficients at their last sweep (`_stage`, `implicit_tower`); weights (s, jet size): the
    weight of a change of each coefficient of G[i] in that measure (`_stage_weights`); defect
    (s, n, jet size): what the first sweep of a step is predicted to add to G, and defects (jet
    degree + 1,): its measure per degree (`_predict`, `_learn`); stage_newton: the work arrays of
    `_stage_newton`.
    """

    work: TapeWork
    G: np.ndarray
    psi: np.ndarray
    Jpsi: np.ndarray
    alpha: np.ndarray
    Jalpha: np.ndarray
    x: np.ndarray
    delta: np.ndarray
    res: np.ndarray
    LU: np.ndarray
    perm: np.ndarray
    v: np.ndarray
    hist: np.ndarray
    memo: np.ndarray
    y: np.ndarray
    y_next: np.ndarray
    Gx: np.ndarray
    changes: np.ndarray
    weights: np.ndarray
    defect: np.ndarray
    defects: np.ndarray
    stage_newton: StageNewtonWork


class StageSolve(NamedTuple):
    """How the towers compute the stages (passed to compiled code as it is for an implicit
    tableau; the compiled loop takes None for an explicit one, `tower_substep.compiled_stage`).

    degree 0: an explicit tableau, each stage once at its exact degree (`tower`); degree D >= 1:
    an implicit tableau, every stage function a jet of degree D solved by sweeps
    (`implicit_tower`), at most `max_sweeps` in one tower.
    """

    degree: int
    max_sweeps: int


class StepTableau(NamedTuple):
    """An RKHP step: the tableau's A (s, s) and b (s,), and the step size h."""

    A: np.ndarray
    b: np.ndarray
    h: float


class Solver(NamedTuple):
    """Newton's tolerance and iteration limit (`rkhp.integrators.newton`), and the system's domain
    code (`state_failure`)."""

    tol: float
    max_iter: int
    domain: int


STAGE_NEWTON_MAX_UNKNOWNS = 1500
"""Most coefficients (stages x components x monomials of degree < D) that `_stage_newton` solves
for: its Jacobian takes 8 N^2 bytes (18 MB) and its factorisation N^3 / 3 operations (about a
second); beyond, stalled sweeps end the step as they did (STAGES_NO_CONVERGENCE)."""


class StageNewtonWork(NamedTuple):
    """The work arrays of `_stage_newton` for N unknowns (N = 0: none, the fallback is off): the
    factorised Jacobian J (N, N) and its row order perm, kept between calls (memo slot
    MEMO_JACOBIAN_KEPT says whether it holds one); u, r, trial, rt, tmp (N,): iterate, residual,
    correction, trial point and its residual; start (N,): the polynomials it started from (given
    back when it fails)."""

    J: np.ndarray
    perm: np.ndarray
    u: np.ndarray
    r: np.ndarray
    trial: np.ndarray
    rt: np.ndarray
    tmp: np.ndarray
    start: np.ndarray


def stage_newton_work(unknowns: int) -> StageNewtonWork:
    """Work arrays for `unknowns` coefficients (none above STAGE_NEWTON_MAX_UNKNOWNS)."""
    N = unknowns if 0 < unknowns <= STAGE_NEWTON_MAX_UNKNOWNS else 0
    return StageNewtonWork(J=np.zeros((N, N)), perm=np.zeros(N, np.int64), u=np.zeros(N), r=np.zeros(N),
                           trial=np.zeros(N), rt=np.zeros(N), tmp=np.zeros(N), start=np.zeros(N))


def step_buffers(tapes: SystemTapes, n: int, s: int, space, stage_degree: int = 0) -> StepBuffers:
    """The work arrays of the step loop for dimension n, s stages and a jet space; with an implicit
    tableau's `stage_degree` D, also those of `_stage_newton` (s n counts[D - 1] unknowns)."""
    size = space.size
    unknowns = s * n * int(space.counts[stage_degree - 1]) if stage_degree > 0 else 0

    def vec():
        return np.zeros(n)

    def mat():
        return np.zeros((n, n))

    return StepBuffers(
        work=tape_work(tapes, size), G=np.zeros((s, n, size)), psi=vec(), Jpsi=mat(), alpha=vec(),
        Jalpha=mat(), x=vec(), delta=vec(), res=vec(), LU=mat(), perm=np.zeros(n, np.int64), v=vec(),
        hist=np.zeros((3, n)), memo=np.zeros(MEMO_SIZE), y=vec(), y_next=vec(), Gx=vec(),
        changes=np.zeros(space.degree + 1), weights=np.zeros((s, size)), defect=np.zeros((s, n, size)),
        defects=np.zeros(space.degree + 1), stage_newton=stage_newton_work(unknowns))


@nb.njit(**NJIT_NORC)
def state_failure(y, domain):
    """The one step validator of every integrator: Failure.NON_FINITE if a component of y is not
    finite, Failure.LEFT_DOMAIN if y is outside the domain (code of `rkhp.systems.core.DOMAINS`),
    else Failure.OK."""
    for k in range(y.shape[0]):
        if not np.isfinite(y[k]):
            return Failure.NON_FINITE
    if domain == POSITIVE_ORTHANT:
        for k in range(y.shape[0]):
            if not y[k] > 0.0:
                return Failure.LEFT_DOMAIN
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def interpreted(tapes, run, space, work):
    """`Interpreted`: the system's tapes, the address `run` of their interpreter and the addresses
    of copies of the tapes, `space` and `work` on the stack of the loop that calls this (inlined
    there: `address_of`), which live as long as its run."""
    return Interpreted(tapes.f, tapes.h, tapes.alpha, tapes.beta, run, address_of(tapes.f),
                       address_of(tapes.h), address_of(tapes.alpha), address_of(tapes.beta),
                       address_of(space), address_of(work))
