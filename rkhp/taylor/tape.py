"""Straight-line programs ("tapes") of operations, recorded by operator overloading.

A system describes H, alpha and beta as tapes over the 2n inputs (x, p); the compiled interpreter
(`rkhp.taylor.interpreter`) evaluates a tape in truncated multivariate Taylor arithmetic, which
is what the RKHP step needs (docs/theory.md §7, "Taylor tower"). A tape is data, so one
compilation of the interpreter serves every system.

A :class:`Tape` is a NamedTuple that the compiled code takes as it is (no positional packing):

- ``ops`` (m, 5) int64 rows (code, out, a, b, k) and ``fpar`` (m,) float64: `out` receives the
  result, `a`, `b` are operand slots, `k` an integer and `fpar[row]` a float parameter (the codes
  and kinds: `rkhp.taylor.ops`);
- ``args`` int64: the operand lists of the operations that have one (CRB, composite ops): such a
  row has ``a`` = start of its list in ``args`` and ``b`` = its length; its results are the slots
  out, out + 1, ...;
- ``outputs`` int64: the result slots; ``n_inputs``, ``n_slots``;
- ``main``: the first row of the main program. Rows ``0..main-1`` hold the sub-programs that
  composite operations evaluate (:meth:`TapeBuilder.subprogram`): the interpreter's main loop
  runs rows ``main..m-1`` only;
- ``scratch_rows``: rows of scratch space its evaluation needs (`rkhp.taylor.interpreter`).

Composite operations and sub-programs (docs/engine.md "Composite operations"):
:meth:`TapeBuilder.composite` records an operation with an operand list and several results;
:meth:`TapeBuilder.subprogram` records a program over its own input slots, kept apart from the
main program, for a composite operation to evaluate (possibly many times, on jets it sets up)
through `rkhp.taylor.interpreter.run_rows`. Its reference, :meth:`SubProgram.operands` (row
range, input and output slots), goes at the head of the composite operation's operand list.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import NamedTuple

import numpy as np

from .ops import (
    ADD,
    ADDC,
    BY_CODE,
    COMPOSITE,
    CONST,
    CRB,
    DERIVED,
    DIV,
    FUNCTION,
    MUL,
    MULC,
    NEG,
    OPS,
    PHIMV,
    POWI,
    POWR,
    SCRATCH_BASE,
    SPRAY,
    SUB,
)


class Tape(NamedTuple):
    """A recorded program (see the module docstring); passed to compiled code as it is.

    The class of a tape names the composite operations it may hold (`composites`): `Tape`
    itself none, `tape_class(codes)` those codes. numba compiles the interpreter once per class,
    with the kernels of its composite operations only, so that a system without them never
    compiles them (`rkhp.taylor.interpreter`; docs/engine.md "Compile time").
    """

    ops: np.ndarray
    fpar: np.ndarray
    args: np.ndarray
    outputs: np.ndarray
    n_inputs: int
    n_slots: int
    main: int
    scratch_rows: int

    composites = ()


def _composite_class(name: str, codes: tuple[int, ...]) -> type:
    cls = type(name, (Tape,), {"__slots__": (), "composites": codes, "__module__": __name__,
                               "__qualname__": name,
                               "__doc__": f"A tape that may hold the composite codes {codes}."})
    globals()[name] = cls  # a module attribute, so that numba's cache can name the class
    return cls


_COMPOSITE_CODES = tuple(op.code for op in OPS if op.kind == COMPOSITE)
#: composite codes -> the tape class holding them: none, each one alone, or all of them
TAPE_CLASSES: dict[tuple[int, ...], type] = {
    (): Tape,
    **{(op.code,): _composite_class(f"Tape_{op.name}", (op.code,))
       for op in OPS if op.kind == COMPOSITE},
    _COMPOSITE_CODES: _composite_class("Tape_composite", _COMPOSITE_CODES),
}


def tape_class(codes) -> type:
    """The tape class for a set of composite codes (all composite kernels for several)."""
    key = tuple(sorted(set(codes)))
    return TAPE_CLASSES.get(key, TAPE_CLASSES[_COMPOSITE_CODES])


def common_class(tapes) -> tuple[Tape, ...]:
    """The tapes as instances of one class, the one whose composite codes cover all of theirs
    (the tapes of one system then share one compiled interpreter)."""
    cls = tape_class(c for t in tapes for c in t.composites)
    return tuple(t if type(t) is cls else cls(*t) for t in tapes)


class Var:
    """A value on a tape under construction (supports + - * / ** with Vars and numbers)."""

    __slots__ = ("builder", "slot")

    def __init__(self, builder: TapeBuilder, slot: int):
        self.builder = builder
        self.slot = slot

    def _lift(self, other) -> Var:
        return other if isinstance(other, Var) else self.builder.const(float(other))

    def __add__(self, other):
        if not isinstance(other, Var):
            return self if float(other) == 0.0 else self.builder.emit(ADDC, self, f=float(other))
        return self.builder.emit(ADD, self, other)

    __radd__ = __add__

    def __sub__(self, other):
        if not isinstance(other, Var):
            return self + (-float(other))
        return self.builder.emit(SUB, self, other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if not isinstance(other, Var):
            value = float(other)
            if value == 1.0:
                return self
            return self.builder.emit(MULC, self, f=value)
        return self.builder.emit(MUL, self, other)

    __rmul__ = __mul__

    def __truediv__(self, other):
        if not isinstance(other, Var):
            return self * (1.0 / float(other))
        return self.builder.emit(DIV, self, other)

    def __rtruediv__(self, other):
        return self.builder.emit(DIV, self._lift(other), self)

    def __neg__(self):
        return self.builder.emit(NEG, self)

    def __pow__(self, exponent):
        if isinstance(exponent, Var):
            return exp(log(self) * exponent)
        value = float(exponent)
        if value.is_integer():
            return self.builder.emit(POWI, self, k=int(value))
        if value == 0.5:
            return sqrt(self)
        return self.builder.emit(POWR, self, f=value)


@dataclass(frozen=True)
class SubProgram:
    """A program recorded apart from the main one: rows ``lo..hi-1`` of the tape, reading its
    ``inputs`` slots and leaving its results in its ``outputs`` slots."""

    lo: int
    hi: int
    inputs: tuple[int, ...]
    outputs: tuple[int, ...]

    def operands(self) -> list[int]:
        """Its reference in an operand list: lo, hi, n_in, inputs..., n_out, outputs...
        (read in compiled code by `rkhp.taylor.interpreter.subprogram_at`)."""
        return [self.lo, self.hi, len(self.inputs), *self.inputs, len(self.outputs),
                *self.outputs]


class _Recording:
    """Rows being recorded: the main program's or a sub-program's (with its own constants)."""

    def __init__(self):
        self.rows: list[tuple[int, int, int, int, int]] = []
        self.fpar: list[float] = []
        self.consts: dict[float, Var] = {}
        self.own: set[int] | None = None  # a sub-program: the slots it may read


class TapeBuilder:
    """Records operations on `n_inputs` input slots (x_1..x_n then p_1..p_n for a system)."""

    def __init__(self, n_inputs: int):
        self.n_inputs = n_inputs
        self.n_slots = n_inputs
        self.args: list[int] = []
        self._main = _Recording()
        self._sub_rows: list[tuple[int, int, int, int, int]] = []
        self._sub_fpar: list[float] = []
        self._current = self._main
        self._scratch = SCRATCH_BASE

    def inputs(self) -> list[Var]:
        return [Var(self, i) for i in range(self.n_inputs)]

    def _new_slots(self, count: int) -> int:
        first = self.n_slots
        self.n_slots += count
        if self._current.own is not None:
            self._current.own.update(range(first, first + count))
        return first

    def _check(self, slots) -> None:
        own = self._current.own
        if own is not None and any(s not in own for s in slots):
            raise ValueError("a sub-program may only use its own inputs and the values it computes")

    def _row(self, code: int, out: int, a: int, b: int, k: int, f: float) -> None:
        self._current.rows.append((code, out, a, b, k))
        self._current.fpar.append(f)

    def emit(self, code: int, a: Var | None = None, b: Var | None = None, k: int = 0,
             f: float = 0.0) -> Var:
        """Record one operation with operand slots a, b (ARITHMETIC and FUNCTION ops)."""
        self._check([v.slot for v in (a, b) if v is not None])
        out = self._new_slots(1)
        self._row(code, out, -1 if a is None else a.slot, -1 if b is None else b.slot, k, f)
        return Var(self, out)

    def const(self, value: float) -> Var:
        consts = self._current.consts
        if value not in consts:
            consts[value] = self.emit(CONST, f=value)
        return consts[value]

    def lift(self, value) -> Var:
        """A Var as it is, a number as a constant of the program being recorded."""
        return value if isinstance(value, Var) else self.const(float(value))

    def _operand_list(self, entries: list[int]) -> tuple[int, int]:
        start = len(self.args)
        self.args.extend(entries)
        return start, len(entries)

    def composite(self, code: int, operands, n_outputs: int, *, k: int = 0, f: float = 0.0,
                  subprograms: tuple[SubProgram, ...] = ()) -> list[Var]:
        """Record a composite operation (kind COMPOSITE in `rkhp.taylor.ops`): its operand list
        is the references of `subprograms` (:meth:`SubProgram.operands`, in order) followed by
        the slots of `operands` (numbers become constants, read by kernels as W[slot, 0]); its
        results are `n_outputs` consecutive slots. Not allowed inside a sub-program (the
        interpreter evaluates sub-programs without recursion)."""
        op = BY_CODE[code]
        if op.kind != COMPOSITE:
            raise ValueError(f"{op.name} is not a composite operation")
        if self._current.own is not None:
            raise ValueError("a sub-program may not contain composite operations")
        slots = [self.lift(v).slot for v in operands]
        self._check(slots)
        refs = [i for sub in subprograms for i in sub.operands()]
        start, length = self._operand_list(refs + slots)
        out = self._new_slots(n_outputs)
        self._row(code, out, start, length, k, f)
        self._scratch = max(self._scratch, SCRATCH_BASE + op.scratch(k))
        return [Var(self, out + i) for i in range(n_outputs)]

    def subprogram(self, n_inputs: int, program) -> SubProgram:
        """Record `program(inputs) -> list of outputs` (inputs: `n_inputs` fresh slots) as a
        sub-program: its rows go to the sub-program part of the tape (rows before `main`), its
        constants are its own, and it may use only its inputs and what it computes (elementary
        operations only: no composite operation)."""
        if self._current.own is not None:
            raise ValueError("sub-programs do not nest")
        outer = self._current
        self._current = _Recording()
        self._current.own = set()
        try:
            first = self._new_slots(n_inputs)
            outputs = program([Var(self, first + i) for i in range(n_inputs)])
            out_slots = tuple(self.lift(v).slot for v in outputs)
            self._check(out_slots)
            lo = len(self._sub_rows)
            self._sub_rows.extend(self._current.rows)
            self._sub_fpar.extend(self._current.fpar)
        finally:
            self._current = outer
        return SubProgram(lo, len(self._sub_rows), tuple(range(first, first + n_inputs)),
                          out_slots)

    def finish(self, outputs) -> Tape:
        slots = [self.lift(v).slot for v in outputs]
        rows = np.array(self._sub_rows + self._main.rows, dtype=np.int64).reshape(-1, 5)
        cls = tape_class(code for code, *_ in self._main.rows if BY_CODE[code].kind == COMPOSITE)
        return cls(rows, np.array(self._sub_fpar + self._main.fpar, dtype=np.float64),
                    np.array(self.args + [0], dtype=np.int64), np.array(slots, dtype=np.int64),
                    self.n_inputs, self.n_slots, len(self._sub_rows), self._scratch)


def _unary(code: int):
    """The recorder of a FUNCTION op; on a value of another arithmetic (e.g. the series of
    `rkhp.systems.spray`) it calls that value's method of the same name, or else its
    ``apply(op)`` with the op's row (for functions that arithmetic knows by their derivative)."""
    row = BY_CODE[code]
    name = row.name

    def unary_op(v):
        if isinstance(v, Var):
            return v.builder.emit(code, v)
        method = getattr(v, name, None)
        if method is not None:
            return method()
        if row.derivative is not None and hasattr(v, "apply"):
            return v.apply(row)
        raise TypeError("tape functions take tape values")

    unary_op.__name__ = name
    return unary_op


#: the FUNCTION ops as recorders of tape Vars, by name (exp, log, sin, cos, sqrt, ...)
_PRIMITIVE = {op.name: _unary(op.code) for op in OPS if op.kind == FUNCTION and op.arity == 1}
exp, log, sin, cos = _PRIMITIVE["exp"], _PRIMITIVE["log"], _PRIMITIVE["sin"], _PRIMITIVE["cos"]
sqrt = _PRIMITIVE["sqrt"]
del _PRIMITIVE["powi"], _PRIMITIVE["powr"]  # recorded by ** (Var.__pow__)


def _derived(d):
    def derived_op(v):
        return d.expand(_NAMESPACE, v)

    derived_op.__name__ = d.name
    return derived_op


_NAMESPACE = SimpleNamespace(**_PRIMITIVE)

#: sympy function name -> recorder of tape Vars: what `rkhp.systems.spec` records
RECORDERS = {**{op.sympy: _PRIMITIVE[op.name] for op in OPS if op.name in _PRIMITIVE and op.sympy},
             **{d.sympy: _derived(d) for d in DERIVED}}


def crb(p: list[Var]) -> Var:
    """c(|p|^2), c(u) = (1 - (sqrt(u)/2) cot(sqrt(u)/2)) / u: the so(3)* coefficient
    (docs/theory.md §4).

    Its operand list is the slot of u = |p|^2 and the slots of p, so that the interpreter can form
    |p|^2 in double-double where c is ill-conditioned (near |p| = 2 pi)."""
    builder = p[0].builder
    u = sum(v * v for v in p)
    builder._check([u.slot] + [v.slot for v in p])
    start, length = builder._operand_list([u.slot] + [v.slot for v in p])
    out = builder._new_slots(1)
    builder._row(CRB, out, start, length, 0, 0.0)
    return Var(builder, out)


def record_phimv(K: list[list], x: list) -> list[Var]:
    """phi(K) x with phi(z) = z / (1 - exp(-z)) (docs/theory.md §4, Lie–Poisson realisation):
    a composite operation whose operand list is K row-major, then x."""
    builder = next(v.builder for v in [*x, *(e for row in K for e in row)] if isinstance(v, Var))
    n = len(x)
    return builder.composite(PHIMV, [v for row in K for v in row] + list(x), n, k=n)


def degree_in(rows, inputs, outputs) -> float:
    """The largest polynomial degree of the `outputs` slots in the `inputs` slots, over rows
    (code, out, a, b, k) of a program: inf where an output is not polynomial in them (a function
    or a divisor that depends on them); other slots are constants (degree 0)."""
    degree = dict.fromkeys(inputs, 1.0)

    def degree_of(slot):
        return degree.get(slot, 0.0)

    for code, out, a, b, k in rows:
        if code == CONST:
            d = 0.0
        elif code == MUL:
            d = degree_of(a) + degree_of(b)
        elif code in (ADD, SUB):
            d = max(degree_of(a), degree_of(b))
        elif code in (NEG, MULC, ADDC):
            d = degree_of(a)
        elif code == DIV:
            d = degree_of(a) if degree_of(b) == 0.0 else math.inf
        elif code == POWI and k >= 0:
            d = k * degree_of(a) if k > 0 else 0.0
        elif code == CRB:  # a, b: its operand list, not slots
            d = math.inf
        else:
            d = 0.0 if degree_of(a) == 0.0 and degree_of(b) == 0.0 else math.inf
        degree[out] = d
    return max((degree_of(s) for s in outputs), default=0.0)


def record_spray(poisson, x: list, p: list) -> list[Var]:
    """alpha and beta of the Poisson-spray realisation of pi (docs/theory.md §9.3), 2n Vars:
    a composite operation whose sub-program is X(y, p) = pi(y) p (`poisson(y)`: the n x n
    entries of pi, numbers or values computed from y) and whose operands are x, then p. Its
    float parameter is 1.0 when X is affine in y (pi affine: constant, Lie–Poisson), which lets
    the kernel sum the Bernoulli series (docs/theory.md §9.3, "X affine in y"), else 0.0."""
    builder = next(v.builder for v in [*x, *p] if isinstance(v, Var))
    n = len(x)

    def field(inputs):
        y, q = inputs[:n], inputs[n:]
        P = poisson(y)
        out = []
        for i in range(n):
            terms = [P[i][j] * q[j] for j in range(n)
                     if isinstance(P[i][j], Var) or float(P[i][j]) != 0.0]
            out.append(sum(terms[1:], terms[0]) if terms else 0.0)
        return out

    sub = builder.subprogram(2 * n, field)
    affine = degree_in(builder._sub_rows[sub.lo:sub.hi], sub.inputs[:n], sub.outputs) <= 1.0
    return builder.composite(SPRAY, list(x) + list(p), 2 * n, k=n, f=1.0 if affine else 0.0,
                             subprograms=(sub,))


#: the functions a family's base program calls on tape Vars (`rkhp.systems.families`)
functions = SimpleNamespace(**_PRIMITIVE, crb=crb, phimv=record_phimv, spray=record_spray)


def record_tape(n: int, program) -> Tape:
    """Record `program(x, p) -> list of outputs` (x, p lists of n Vars) as a tape on 2n inputs."""
    builder = TapeBuilder(2 * n)
    v = builder.inputs()
    return builder.finish(program(v[:n], v[n:]))

