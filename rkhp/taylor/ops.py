"""The operations of a tape: one table (docs/engine.md "The opcode table").

Every operation a tape can hold is one :class:`Op` row of :data:`OPS`: its name, its integer code
(what the compiled interpreter dispatches on), its kind, its arity and, for the functions a spec
file may call, the sympy function it implements and the float function the expression reader uses
to bound constant sizes. Three kinds:

- ``ARITHMETIC`` (codes 0..7, and POWI with k >= 0): + - * / with slots and float constants,
  evaluated in place by the interpreter (`rkhp.taylor.interpreter`);
- ``FUNCTION`` (codes 8..63): univariate elementary functions u -> f(u). Each has ONE compiled
  Taylor recurrence, `rkhp.taylor.elementary.taylor_coefficients`, giving f^(q)(u0)/q! for
  q = 0..D; the interpreter composes it with the jet of u (degree D) or, at degree 0, takes the
  value coef[0]. DIV uses the reciprocal's coefficients (code DIV), POWI with k < 0 those of
  u^k. CRB lists further operand slots (see `rkhp.taylor.tape.crb`);
- ``COMPOSITE`` (codes 64 and up): operations with an operand list, several results and, if they
  need one, sub-programs stored in the same tape (docs/engine.md "Composite operations"). Each
  has a compiled kernel called from `rkhp.taylor.interpreter._composite`, and declares the
  scratch rows it needs beyond the interpreter's own (:attr:`Op.scratch`).

:data:`FUNCTIONS` are the functions of mathematical text (`rkhp.base.expressions` reads exactly these
names; `rkhp.systems.spec` records them): the FUNCTION ops with a sympy name, and derived functions
recorded as compositions of them (tan = sin/cos, ...).

Adding an elementary function: a code constant, one :data:`OPS` row with its sympy name, float
function and derivative, and its Taylor recurrence in `rkhp.taylor.elementary.taylor_coefficients`
(docs/engine.md "Adding an elementary function").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

ARITHMETIC, FUNCTION, COMPOSITE = "arithmetic", "function", "composite"

#: collocation nodes of the spray kernel at most (`rkhp.taylor.collocation`,
#: `rkhp.taylor.composites.spray`)
SPRAY_MAX_NODES = 24

CONST, ADD, SUB, MUL, NEG, MULC, ADDC, DIV = 0, 1, 2, 3, 4, 5, 6, 7
EXP, LOG, SIN, COS, SQRT, POWI, POWR, CRB = 8, 9, 10, 11, 12, 13, 14, 15
ATAN = 16
FIRST_COMPOSITE = 64
PHIMV, SPRAY = 64, 65

#: The one scratch layout of an evaluation (rows of the scratch array S, each a jet):
#: jet_compose's argument, accumulator and product rows; a temporary row (DIV's reciprocal,
#: POWI's powers); the univariate Taylor coefficients; composite kernels use the rows from
#: SCRATCH_BASE on, as many as their :attr:`Op.scratch` declares (`Tape.scratch_rows`).
COMPOSE_ARG, COMPOSE_ACC, COMPOSE_PROD, TEMP_ROW, COEF_ROW, SCRATCH_BASE = 0, 1, 2, 3, 4, 5


@dataclass(frozen=True)
class Op:
    """One operation of the tape.

    Attributes:
        name: its name (the function's name in mathematical text for FUNCTION ops with `sympy`).
        code: the opcode (kinds by range: < 8 arithmetic, 8..63 function, >= 64 composite).
        kind: ARITHMETIC, FUNCTION or COMPOSITE.
        arity: operand slots in the row (a, b); -1 for an operand list in `args`.
        sympy: the sympy function it implements (None: not callable from mathematical text).
        value: the float function (`math`), for the expression reader's size bounds.
        scratch: COMPOSITE ops: scratch rows the kernel needs given the row's k.
        derivative: FUNCTION ops without a recurrence of their own in the series arithmetic of
            the truncated spray realisation (`rkhp.systems.spray`): f'(u) written with + - * /
            and the table's functions (`derivative(f, u)`, f the namespace of functions), from
            which that arithmetic applies the function by the chain rule.
    """

    name: str
    code: int
    kind: str
    arity: int
    sympy: str | None = None
    value: Callable[[float], float] | None = None
    scratch: Callable[[int], int] | None = None
    derivative: Callable | None = None


OPS: tuple[Op, ...] = (
    Op("const", CONST, ARITHMETIC, 0),
    Op("add", ADD, ARITHMETIC, 2),
    Op("sub", SUB, ARITHMETIC, 2),
    Op("mul", MUL, ARITHMETIC, 2),
    Op("neg", NEG, ARITHMETIC, 1),
    Op("mulc", MULC, ARITHMETIC, 1),
    Op("addc", ADDC, ARITHMETIC, 1),
    Op("div", DIV, ARITHMETIC, 2),
    Op("exp", EXP, FUNCTION, 1, "exp", math.exp),
    Op("log", LOG, FUNCTION, 1, "log", math.log),
    Op("sin", SIN, FUNCTION, 1, "sin", math.sin),
    Op("cos", COS, FUNCTION, 1, "cos", math.cos),
    Op("sqrt", SQRT, FUNCTION, 1, "sqrt", math.sqrt),
    Op("powi", POWI, FUNCTION, 1),
    Op("powr", POWR, FUNCTION, 1),
    Op("crb", CRB, FUNCTION, -1),
    Op("atan", ATAN, FUNCTION, 1, "atan", math.atan, derivative=lambda f, u: 1.0 / (1.0 + u * u)),
    # phi(K) x, K (n x n) and x listed in args: scratch rows v = K^k x, K v and one product
    Op("phimv", PHIMV, COMPOSITE, -1, scratch=lambda n: 2 * n + 1),
    # the Poisson-spray realisation (alpha, beta) of pi (docs/theory.md §9.3): a sub-program
    # X(y, p) = pi(y) p, then x and p; scratch rows: the stage values and their X, for up to
    # SPRAY_MAX_NODES collocation nodes (`rkhp.taylor.collocation`)
    Op("spray", SPRAY, COMPOSITE, -1, scratch=lambda n: 2 * SPRAY_MAX_NODES * n),
)

BY_CODE: dict[int, Op] = {op.code: op for op in OPS}
BY_NAME: dict[str, Op] = {op.name: op for op in OPS}


@dataclass(frozen=True)
class Derived:
    """A function of mathematical text recorded as a composition of tape functions:
    `expand(f, u)` with `f` the namespace of recorded functions (f.sin, f.exp, ...)."""

    name: str
    sympy: str
    value: Callable[[float], float]
    expand: Callable


def _tan(f, u):
    return f.sin(u) / f.cos(u)


def _sinh(f, u):
    return 0.5 * (f.exp(u) - f.exp(-u))


def _cosh(f, u):
    return 0.5 * (f.exp(u) + f.exp(-u))


def _tanh(f, u):
    ep, em = f.exp(u), f.exp(-u)
    return (ep - em) / (ep + em)


DERIVED: tuple[Derived, ...] = (
    Derived("tan", "tan", math.tan, _tan),
    Derived("sinh", "sinh", math.sinh, _sinh),
    Derived("cosh", "cosh", math.cosh, _cosh),
    Derived("tanh", "tanh", math.tanh, _tanh),
)

#: name in mathematical text -> (sympy function name, float function): what the reader allows
FUNCTIONS: dict[str, tuple[str, Callable[[float], float]]] = {
    **{op.name: (op.sympy, op.value) for op in OPS if op.sympy is not None},
    **{d.name: (d.sympy, d.value) for d in DERIVED},
}
