"""The Poisson-spray birealisation of any Poisson matrix, as a series in p (docs/theory.md §9).

Let Phi_s^p be the flow of y' = pi(y) p (p frozen). alpha(x, p) solves
int_0^1 Phi_s^p(alpha) ds = x and beta(x, p) = Phi_1^p(alpha(x, p)) (Weinstein's Poisson spray in
Darboux form; Crainic–Mărcuț arXiv:1009.2085, Cabrera–Dherin arXiv:1212.5999). It is symmetric:
beta(x, p) = alpha(x, -p).

Truncated realisation ``truncated:K``. Scale p -> eps p: the flow Y(s, eps) = Phi_{eps s}^p(a(eps))
has Y = sum_m Y_m(s) eps^m with Y_0 = x, dY_m/ds = F_{m-1}(s), F_k the eps-coefficient k of
pi(Y(s, eps)) p, and int_0^1 Y_m ds = 0 for m >= 1. Hence

    a_m = Y_m(0) = -int_0^1 (1 - s) F_{m-1}(s) ds,   Y_m(s) = a_m + int_0^s F_{m-1},
    alpha_K = x + sum_{m=1}^K a_m,                    beta_K = x + sum_{m=1}^K (-1)^m a_m,

a_m homogeneous of degree m in p (a_1 = -pi(x) p / 2). F_{m-1} is a polynomial of degree m - 1 in
s, so it is represented by its values at the K Gauss–Legendre nodes of [0, 1] (exact for degree
<= K - 1), and the integrals are exact quadratures on those values
(`rkhp.taylor.collocation`).
At each node the eps-coefficients of pi(Y) are computed order by order by the standard
Taylor-mode recurrences (products, quotients, exp, log, sin, cos, real powers) on tape values,
so the whole series is recorded on the tape at record time (:class:`Series`).

With symmetric nodes, beta_K(x, p) = alpha_K(x, -p) equals the truncated end value
x + sum_m Y_m(1) exactly in exact arithmetic (tests check it).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..taylor import tape as tp
from ..taylor.collocation import collocation

#: largest truncation degree K of ``truncated:K`` (the tape grows like K^3)
MAX_TRUNCATION = 12


# ----------------------------------------------------------------------------------------------
# univariate Taylor series in eps over tape values, evaluated order by order at several nodes


def _is_constant_zero(v) -> bool:
    return not isinstance(v, tp.Var) and float(v) == 0.0


def _add(a, b):
    if _is_constant_zero(a):
        return b
    if _is_constant_zero(b):
        return a
    return a + b


def _mul(a, b):
    if _is_constant_zero(a) or _is_constant_zero(b):
        return 0.0
    if not isinstance(a, tp.Var) and not isinstance(b, tp.Var):
        return float(a) * float(b)
    return a * b


def _sum_vars(values):
    out = 0.0
    for v in values:
        out = _add(out, v)
    return out


def _scale(c: float, v):
    return 0.0 if c == 0.0 or _is_constant_zero(v) else (float(c) * float(v) if not isinstance(v, tp.Var)
                                                else v * c)


class _Graph:
    """The operations recorded on series, in creation (topological) order, and the number of
    nodes Q at which each series is evaluated."""

    def __init__(self, q: int):
        self.q = q
        self.nodes: list[Series] = []


class Series:
    """A truncated Taylor series in eps whose coefficients are tape values (or floats), one per
    quadrature node, computed lazily order by order (:meth:`_Graph` keeps the order).

    ``coef[m][q]`` is coefficient m at node q; coefficient 0 is the same at every node (all
    series start from x). Supports + - * / and ** with series and numbers, and the methods
    exp, log, sin, cos, sqrt (called by the tape functions `rkhp.taylor.tape.exp` etc.), and
    :meth:`apply` for the other functions of the opcode table.
    """

    __slots__ = ("graph", "op", "args", "param", "coef")

    def __init__(self, graph: _Graph, op: str, args=(), param=None):
        self.graph = graph
        self.op = op
        self.args = args
        self.param = param
        self.coef: list[list] = []
        graph.nodes.append(self)

    # -- construction
    def _lift(self, other) -> Series:
        if isinstance(other, Series):
            return other
        return Series(self.graph, "const", (), other)

    def __add__(self, other):
        if isinstance(other, tp.Var):
            return Series(self.graph, "add", (self, self._lift(other)))
        if not isinstance(other, Series):
            return self if _is_constant_zero(other) else Series(self.graph, "shift", (self,), float(other))
        return Series(self.graph, "add", (self, other))

    __radd__ = __add__

    def __sub__(self, other):
        if not isinstance(other, Series | tp.Var):
            return self + (-float(other))
        return Series(self.graph, "sub", (self, self._lift(other)))

    def __rsub__(self, other):
        return Series(self.graph, "sub", (self._lift(other), self))

    def __neg__(self):
        return Series(self.graph, "scale", (self,), -1.0)

    def __mul__(self, other):
        if not isinstance(other, Series):
            if isinstance(other, tp.Var):
                return Series(self.graph, "mul", (self, self._lift(other)))
            return Series(self.graph, "scale", (self,), float(other))
        return Series(self.graph, "mul", (self, other))

    __rmul__ = __mul__

    def __truediv__(self, other):
        if not isinstance(other, Series | tp.Var):
            return self * (1.0 / float(other))
        return Series(self.graph, "div", (self, self._lift(other)))

    def __rtruediv__(self, other):
        return Series(self.graph, "div", (self._lift(other), self))

    def __pow__(self, exponent):
        if isinstance(exponent, Series | tp.Var):
            return (self.log() * exponent).exp()
        value = float(exponent)
        if value.is_integer() and value > 0:
            k = int(value)
            result, base = None, self
            while k:
                if k & 1:
                    result = base if result is None else result * base
                k >>= 1
                if k:
                    base = base * base
            return result
        if value == 0.0:
            return self._lift(1.0)
        return Series(self.graph, "pow", (self,), value)

    def exp(self):
        return Series(self.graph, "exp", (self,))

    def log(self):
        return Series(self.graph, "log", (self,))

    def sqrt(self):
        return Series(self.graph, "pow", (self,), 0.5)

    def sin(self):
        s = Series(self.graph, "sin", (self,))
        c = Series(self.graph, "cos", (self,))
        s.param, c.param = c, s  # each one's recurrence uses the other
        return s

    def cos(self):
        return self.sin().param

    def apply(self, op):
        """f(self) for a FUNCTION op of the opcode table known here only by its derivative
        (`rkhp.taylor.ops.Op.derivative`): w = f(u) has w' = f'(u) u', so
        w_m = (1/m) sum_{k=1}^m k u_k d_{m-k} with d = f'(u), itself a series."""
        return Series(self.graph, "chain", (self, op.derivative(tp.functions, self)), op)

    # -- evaluation of coefficient m (every lower coefficient of every node is known)
    def _value(self, m: int, q: int):
        op, args = self.op, self.args
        if op == "const":
            return self.param if m == 0 else 0.0
        if op == "input":
            raise AssertionError("input coefficients are set by the caller")
        u = args[0].coef
        if op == "add":
            return _add(u[m][q], args[1].coef[m][q])
        if op == "sub":
            return _add(u[m][q], _scale(-1.0, args[1].coef[m][q]))
        if op == "scale":
            return _scale(self.param, u[m][q])
        if op == "shift":
            return _add(u[m][q], self.param) if m == 0 else u[m][q]
        if op == "mul":
            v = args[1].coef
            return _sum_vars(_mul(u[k][q], v[m - k][q]) for k in range(m + 1))
        w = self.coef
        if op == "div":
            v = args[1].coef
            if m == 0:
                return u[0][q] / v[0][q] if isinstance(u[0][q], tp.Var) or isinstance(
                    v[0][q], tp.Var) else float(u[0][q]) / float(v[0][q])
            num = _add(u[m][q], _scale(-1.0, _sum_vars(_mul(v[k][q], w[m - k][q])
                                                  for k in range(1, m + 1))))
            return _div(num, v[0][q])
        if op == "exp":
            if m == 0:
                return _apply(tp.exp, math.exp, u[0][q])
            return _scale(1.0 / m, _sum_vars(_scale(k, _mul(u[k][q], w[m - k][q]))
                                        for k in range(1, m + 1)))
        if op == "log":
            if m == 0:
                return _apply(tp.log, math.log, u[0][q])
            tail = _sum_vars(_scale(k / m, _mul(w[k][q], u[m - k][q])) for k in range(1, m))
            return _div(_add(u[m][q], _scale(-1.0, tail)), u[0][q])
        if op in ("sin", "cos"):
            if m == 0:
                return _apply(getattr(tp, op), getattr(math, op), u[0][q])
            other = self.param.coef
            sign = 1.0 if op == "sin" else -1.0
            return _scale(sign / m, _sum_vars(_scale(k, _mul(u[k][q], other[m - k][q]))
                                         for k in range(1, m + 1)))
        if op == "chain":
            if m == 0:
                return _apply(getattr(tp.functions, self.param.name), self.param.value, u[0][q])
            d = args[1].coef
            return _scale(1.0 / m, _sum_vars(_scale(k, _mul(u[k][q], d[m - k][q])) for k in range(1, m + 1)))
        if op == "pow":
            r = self.param
            if m == 0:
                return u[0][q] ** r if isinstance(u[0][q], tp.Var) else float(u[0][q]) ** r
            acc = _sum_vars(_scale((r + 1.0) * k - m, _mul(u[k][q], w[m - k][q]))
                       for k in range(1, m + 1))
            return _div(_scale(1.0 / m, acc), u[0][q])
        raise AssertionError(f"unknown series operation {op}")


def _apply(tape_function, float_function, v):
    return tape_function(v) if isinstance(v, tp.Var) else float_function(float(v))


def _div(a, b):
    if _is_constant_zero(a):
        return 0.0
    if isinstance(a, tp.Var) or isinstance(b, tp.Var):
        return a / b
    return float(a) / float(b)


def _compute(graph: _Graph, m: int) -> None:
    """Coefficient m of every non-input series, at every node (once for m = 0)."""
    for node in graph.nodes:
        if node.op == "input":
            continue
        if m == 0:
            value = node._value(0, 0)
            node.coef.append([value] * graph.q)
        else:
            node.coef.append([node._value(m, q) for q in range(graph.q)])


class SpraySeries(NamedTuple):
    """The homogeneous terms of the truncated spray realisation: ``start[m - 1]`` = a_m =
    Y_m(0) and ``end[m - 1]`` = Y_m(1), each a list of n tape values (m = 1..K)."""

    start: list
    end: list


def spray_series(poisson, x, p, K: int) -> SpraySeries:
    """a_m and Y_m(1), m = 1..K, of the spray realisation of `poisson` (a program y -> n x n
    entries, each a number or a function of the series y) at tape values x, p (module
    docstring)."""
    n = len(x)
    quad = collocation(K)
    graph = _Graph(K)
    y = [Series(graph, "input") for _ in range(n)]
    for i in range(n):
        y[i].coef.append([x[i]] * K)
    P = poisson(y)
    start, end = [], []
    for m in range(1, K + 1):
        _compute(graph, m - 1)

        def series_entry(v, q, k=m - 1):
            if isinstance(v, Series):
                return v.coef[k][q]
            return v if k == 0 else 0.0

        # F_{m-1}(s_q) = [pi(Y)]_{m-1}(s_q) p
        F = [[_sum_vars(_mul(series_entry(P[i][j], q), p[j]) for j in range(n)) for i in range(n)]
             for q in range(K)]
        a = [_scale(-1.0, _sum_vars(_scale(quad.w[r], F[r][i]) for r in range(K))) for i in range(n)]
        start.append(a)
        end.append([_add(a[i], _sum_vars(_scale(quad.b[r], F[r][i]) for r in range(K)))
                    for i in range(n)])
        if m < K:
            for i in range(n):
                y[i].coef.append([_add(a[i], _sum_vars(_scale(quad.A[q, r], F[r][i])
                                                  for r in range(K))) for q in range(K)])
    return SpraySeries(start, end)


def truncated_realisation(poisson, K: int):
    """(alpha, beta): programs (x, p) -> n tape values of the spray realisation truncated at
    degree K in p: alpha_K = x + sum a_m, beta_K = x + sum (-1)^m a_m (module docstring)."""

    def make(sign: float):
        def spray_program(x, p):
            terms = spray_series(poisson, x, p, K).start
            return [_sum_vars([x[i]] + [_scale(sign**m, terms[m - 1][i]) for m in range(1, K + 1)])
                    for i in range(len(x))]

        return spray_program

    return make(1.0), make(-1.0)


def truncated_order(K: int, poisson_degree: int | None) -> int | None:
    """The largest global order an RKHP method reaches with ``truncated:K`` (docs/theory.md §9).

    With A_m the degree-m term of the spray series (a_m above), the truncated step differs from
    the exact one by sum_{m > K} (1 - (-1)^m) A_m at leading order, plus terms one power of h
    smaller than the first non-zero A_m, m > K. So with m1 the first m > K with A_m != 0 and m2
    the first odd such m, the order is min(m1, m2 - 1). For constant pi every A_m, m >= 2,
    vanishes (no bound); for linear pi the odd ones m >= 3 do (phi(z) - z/2 is even), so the
    bound is the first even m > K; otherwise it is K for even K and K + 1 for odd K.
    """
    if poisson_degree == 0:
        return None
    if poisson_degree == 1:
        return K + 2 if K % 2 == 0 else K + 1
    return K if K % 2 == 0 else K + 1
