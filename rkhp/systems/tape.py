"""Straight-line programs ("tapes") of primitive operations, recorded by operator overloading.

A system describes H, alpha and beta as tapes over the 2n inputs (x, p); the compiled engine
(`rkhp.integrators.jets`) evaluates a tape in truncated multivariate Taylor arithmetic, which is
what the RKHP step needs (docs/theory.md §7, "Taylor tower"). A tape is data, so one compilation of the
interpreter serves every system.

Operations (opcode, out, a, b, k, f): out receives the result; a, b are operand slots; k an
integer parameter; f a float parameter. PHIMV is the only operation with several operands and
results: its operands are `args[a : a + n*n + n]` (K row-major, then x) and it writes
phi(K) x to the n consecutive slots out..out+n-1. CRB (c(u), u = |p|^2) lists p in
`args[b : b + k]`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONST, ADD, SUB, MUL, NEG, MULC, ADDC, DIV = 0, 1, 2, 3, 4, 5, 6, 7
EXP, LOG, SIN, COS, SQRT, POWI, POWR, CRB, PHIMV = 8, 9, 10, 11, 12, 13, 14, 15, 16


@dataclass(frozen=True, eq=False)
class Tape:
    """A recorded program: `ops` (m, 5) int64 rows (opcode, out, a, b, k), `fpar` (m,) float64,
    `args` int64 operand lists (PHIMV), `outputs` int64 result slots, `n_inputs`, `n_slots`."""

    ops: np.ndarray
    fpar: np.ndarray
    args: np.ndarray
    outputs: np.ndarray
    n_inputs: int
    n_slots: int

    def packed(self):
        """The tuple of arrays the compiled interpreter takes."""
        return (self.ops, self.fpar, self.args, self.outputs)


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


class TapeBuilder:
    """Records operations on `n_inputs` input slots (x_1..x_n then p_1..p_n for a system)."""

    def __init__(self, n_inputs: int):
        self.n_inputs = n_inputs
        self.n_slots = n_inputs
        self.rows: list[tuple[int, int, int, int, int]] = []
        self.fpar: list[float] = []
        self.args: list[int] = []
        self._consts: dict[float, Var] = {}

    def inputs(self) -> list[Var]:
        return [Var(self, i) for i in range(self.n_inputs)]

    def _new_slots(self, count: int) -> int:
        first = self.n_slots
        self.n_slots += count
        return first

    def emit(self, code: int, a: Var | None = None, b: Var | None = None, k: int = 0,
             f: float = 0.0) -> Var:
        out = self._new_slots(1)
        self.rows.append((code, out, -1 if a is None else a.slot, -1 if b is None else b.slot, k))
        self.fpar.append(f)
        return Var(self, out)

    def const(self, value: float) -> Var:
        if value not in self._consts:
            self._consts[value] = self.emit(CONST, f=value)
        return self._consts[value]

    def phimv(self, K: list[list[Var]], x: list[Var]) -> list[Var]:
        """phi(K) x with phi(z) = z / (1 - exp(-z)) (docs/theory.md §4, Lie–Poisson realisation)."""
        n = len(x)
        start = len(self.args)
        self.args.extend(self._lift(v).slot for row in K for v in row)
        self.args.extend(self._lift(v).slot for v in x)
        out = self._new_slots(n)
        self.rows.append((PHIMV, out, start, -1, n))
        self.fpar.append(0.0)
        return [Var(self, out + i) for i in range(n)]

    def _lift(self, value) -> Var:
        return value if isinstance(value, Var) else self.const(float(value))

    def finish(self, outputs) -> Tape:
        slots = [self._lift(v).slot for v in outputs]
        rows = np.array(self.rows, dtype=np.int64).reshape(-1, 5)
        return Tape(rows, np.array(self.fpar, dtype=np.float64),
                    np.array(self.args + [0], dtype=np.int64), np.array(slots, dtype=np.int64),
                    self.n_inputs, self.n_slots)


def _unary(code: int, name: str):
    """The tape function `name`; on a value of another arithmetic (e.g. the series of
    `rkhp.systems.spray`) it calls that value's method of the same name."""

    def op(v):
        if isinstance(v, Var):
            return v.builder.emit(code, v)
        method = getattr(v, name, None)
        if method is None:
            raise TypeError("tape functions take tape values")
        return method()

    return op


exp = _unary(EXP, "exp")
log = _unary(LOG, "log")
sin = _unary(SIN, "sin")
cos = _unary(COS, "cos")
sqrt = _unary(SQRT, "sqrt")


def crb(p: list[Var]) -> Var:
    """c(|p|^2), c(u) = (1 - (sqrt(u)/2) cot(sqrt(u)/2)) / u: the so(3)* coefficient (docs/theory.md §4).

    The operation also lists the slots of p, so that the interpreter can form |p|^2 in
    double-double where c is ill-conditioned (near |p| = 2 pi)."""
    builder = p[0].builder
    u = sum(v * v for v in p)
    start = len(builder.args)
    builder.args.extend(v.slot for v in p)
    out = builder._new_slots(1)
    builder.rows.append((CRB, out, u.slot, start, len(p)))
    builder.fpar.append(0.0)
    return Var(builder, out)


def record(n: int, program) -> Tape:
    """Record `program(x, p) -> list of outputs` (x, p lists of n Vars) as a tape on 2n inputs."""
    builder = TapeBuilder(2 * n)
    v = builder.inputs()
    return builder.finish(program(v[:n], v[n:]))
