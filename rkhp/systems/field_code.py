"""The Poisson vector field f(x) = pi(x) grad H(x) written out as plain arithmetic (docs/theory.md §4).

What a user hands an ODE solver is a right-hand side written with plain arithmetic; the peers of
``rkhp bench`` get that field, generated from the system itself, for every system (built-in or
from a spec file):

- pi(x) as sympy expressions from the system's family (the ``symbolic`` member of its
  :class:`~rkhp.systems.families.PoissonFamily`, of ``system.structure``);
- H(x) as a sympy expression read off the system's Hamiltonian tape (`rkhp.taylor.tape`: its
  arithmetic rows and elementary functions, one sympy node per row);
- f_i = sum_j pi_ij dH/dx_j by sympy's differentiation, its common subexpressions named once
  (``sympy.cse``), printed by sympy's Python printer (arithmetic, number literals and ``math.f``
  calls).

The source is built from a tree of rkhp's own making (symbols x1..xn, numbers, + - * / **, the
functions of the opcode table), checked node by node (:func:`check_tree`) before it is printed:
no text of a spec file reaches ``exec``. Three forms (:data:`FORMS`):

- ``numpy``: ``f(t, x) -> ndarray`` for scipy's ``solve_ivp``: the state unpacked to Python floats,
  scalar arithmetic, ``math`` functions, one ``np.array`` built at the end;
- ``cfunc``: ``f(t, u, du, p)`` writing du in place, the signature of a numba ``cfunc`` right-hand
  side (numbalsoda's ``lsoda_sig``);
- ``jax``: ``f(t, y, args) -> array`` for diffrax, the functions of ``jax.numpy``.

The direct forms of the RKHP Euler step take H's gradient and Hessian written out the same way
(:func:`derivatives_code`), and the spray realisation's frozen field with its derivatives
(:func:`spray_code`), compiled per system by `rkhp.taylor.generated`.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import NamedTuple

import numpy as np

from ..base.errors import InputError
from ..taylor import ops
from .families import FAMILIES
from .structure import symbols_of

FORMS = ("numpy", "cfunc", "jax")
#: the functions a field may call: those of the opcode table and its derived ones (`rkhp.taylor.ops`)
FUNCTION_NAMES = ("exp", "log", "sin", "cos", "sqrt", "atan", "tan", "sinh", "cosh", "tanh")


class FieldCode(NamedTuple):
    """A system's field as source: ``source`` defines ``field`` in the form ``form``; ``dim``
    components; ``operations``: the arithmetic operations and function calls of one evaluation
    (sympy's ``count_ops`` of the printed expressions); ``branches``: those of each branch
    ``what`` = 0, 1, ... of a function with branches (:func:`spray_code`), else empty."""

    form: str
    source: str
    dim: int
    operations: int
    branches: tuple[int, ...] = ()


def hamiltonian_expression(system):
    """H(x) as a sympy expression in x1..xn, read off ``system.h_tape`` row by row; InputError
    for a tape holding an operation that has no elementary form (a composite operation)."""
    import sympy

    tape = system.h_tape
    n = system.dim
    x = symbols_of(n)
    slots: dict[int, object] = {i: x[i] for i in range(n)}
    slots.update({n + i: sympy.Integer(0) for i in range(tape.n_inputs - n)})  # p = 0: H reads no p
    functions = {op.code: getattr(sympy, op.sympy) for op in ops.OPS if op.kind == ops.FUNCTION and op.sympy}
    for row in range(int(tape.main), tape.ops.shape[0]):
        code, out, a, b, k = (int(v) for v in tape.ops[row])
        f = sympy.Float(float(tape.fpar[row]))
        A, B = slots.get(a), slots.get(b)
        if code == ops.CONST:
            value = f
        elif code == ops.ADD:
            value = A + B
        elif code == ops.SUB:
            value = A - B
        elif code == ops.MUL:
            value = A * B
        elif code == ops.NEG:
            value = -A
        elif code == ops.MULC:
            value = A * f
        elif code == ops.ADDC:
            value = A + f
        elif code == ops.DIV:
            value = A / B
        elif code == ops.POWI:
            value = A ** sympy.Integer(k)
        elif code == ops.POWR:
            value = A ** f
        elif code in functions:
            value = functions[code](A)
        else:
            raise InputError(f"{system.name}: its Hamiltonian holds the operation {ops.BY_CODE[code].name}, "
                             "which has no plain-arithmetic form")
        slots[out] = value
    return slots[int(tape.outputs[0])]


def poisson_expressions(system):
    """pi(x) as rows of sympy expressions in x1..xn, from the system's family and structure."""
    family = FAMILIES.get(system.family)
    if family is None or family.symbolic is None or system.structure is None:
        raise InputError(f"{system.name}: its Poisson matrix has no symbolic form (family {system.family})")
    return family.symbolic(system.structure)


def field_expressions(system):
    """(symbols x1..xn, [f_1..f_n]) with f = pi(x) grad H(x), as sympy expressions."""
    import sympy

    x = symbols_of(system.dim)
    H = hamiltonian_expression(system)
    grad = [sympy.diff(H, s) for s in x]
    pi = poisson_expressions(system)
    return x, [sympy.Add(*[pi[i][j] * grad[j] for j in range(system.dim) if pi[i][j] != 0 and grad[j] != 0])
               for i in range(system.dim)]


def check_tree(expr) -> None:
    """InputError unless ``expr`` holds only numbers, symbols, pi and E, + * ** and the functions
    of :data:`FUNCTION_NAMES` (what the printer turns into arithmetic and ``math.f`` calls)."""
    import sympy

    for node in sympy.preorder_traversal(expr):
        if isinstance(node, sympy.Number | sympy.Symbol | sympy.Add | sympy.Mul | sympy.Pow):
            continue
        if node in (sympy.pi, sympy.E):
            continue
        if isinstance(node, sympy.Function) and type(node).__name__ in FUNCTION_NAMES:
            continue
        raise InputError(f"the vector field holds {type(node).__name__}, which has no plain-arithmetic form")


LARGEST_LITERAL = 2**63 - 1
"""The largest integer literal numba types (as int64; its type inference refuses a larger one,
and a negative integer is printed as the negation of its magnitude)."""


def _literal_fits(value: int) -> bool:
    """Whether numba types the printed integer ``value`` (:data:`LARGEST_LITERAL`)."""
    return abs(value) <= LARGEST_LITERAL


def float_literal(p: int, q: int = 1) -> str:
    """The float64 nearest p/q as a literal (Python's integer division is correctly rounded, so
    the value is exact where p/q is a float64, as 10^19 = 2^19 5^19 is): the value a float64
    field computes with. InputError where p/q is beyond the float range or a nonzero p/q
    rounds to 0."""
    try:
        value = p / q
    except OverflowError:
        value = math.inf
    if not math.isfinite(value) or (value == 0 and p != 0):
        bound = "beyond the float range (|x| > 1.8e308)" if value else "below the float range (|x| < 4.9e-324)"
        raise InputError(f"the vector field holds a constant {bound}, which float arithmetic cannot represent")
    return repr(value)


def _printer():
    """sympy's Python printer, with

    - a negative integer power written as a division, 1.0/(x**k): numba raises
      ZeroDivisionError for 0.0 to a negative integer power whatever the error model, and a
      ``cfunc`` cannot pass an exception on (it says so on stderr and leaves its outputs
      unwritten), where the division gives inf, as the tapes do, and the substep fails with its
      cause;
    - an integer, or a rational's numerator or denominator, beyond :data:`LARGEST_LITERAL`
      written as the nearest float64 (:func:`float_literal`): a spec file's ``1e19`` is read
      exactly as an integer (`rkhp.base.expressions`), which numba cannot type."""
    import sympy
    from sympy.printing.pycode import PythonCodePrinter

    class Printer(PythonCodePrinter):
        def _print_Pow(self, expr, rational=False):
            if expr.exp.is_Integer and expr.exp < 0:
                return f"1.0/({self._print(sympy.Pow(expr.base, -expr.exp))})"
            return super()._print_Pow(expr, rational=rational)

        def _print_Integer(self, expr):
            return super()._print_Integer(expr) if _literal_fits(expr.p) else float_literal(expr.p)

        def _print_Rational(self, expr):
            if _literal_fits(expr.p) and _literal_fits(expr.q):
                return super()._print_Rational(expr)
            return float_literal(expr.p, expr.q)

    return Printer({"fully_qualified_modules": True, "standard": "python3"})


def _printed(symbols, exprs) -> tuple[list[tuple[str, str]], list[str], int]:
    """(named subexpressions, the components, operation count) as Python text; x_i is named xi."""
    import sympy

    for e in exprs:
        check_tree(e)
    names = sympy.numbered_symbols("c")
    common, reduced = sympy.cse(exprs, symbols=names, order="none")
    printer = _printer()
    lines = [(str(s), printer.doprint(e)) for s, e in common]
    components = [printer.doprint(sympy.Float(0.0) if e == 0 else e) for e in reduced]
    count = int(sum(sympy.count_ops(e) for _, e in common) + sum(sympy.count_ops(e) for e in reduced))
    return lines, components, count


def field_code(system, form: str) -> FieldCode:
    """The source of the system's field in ``form`` (:data:`FORMS`), defining ``field``."""
    if form not in FORMS:
        raise InputError(f"unknown form {form!r} of the field; choose one of {', '.join(FORMS)}")
    symbols, exprs = field_expressions(system)
    return code_of(symbols, exprs, form)


def code_of(symbols, exprs, form: str) -> FieldCode:
    """:func:`field_code` of given expressions (``symbols`` named x1..xn)."""
    lines, components, count = _printed(symbols, exprs)
    n = len(symbols)
    names = [str(s) for s in symbols]
    body = [f"    {name} = {text}" for name, text in lines]
    if form == "numpy":
        head = ["def field(t, x):", f"    {', '.join(names)}{',' if n == 1 else ''} = x.tolist()"]
        tail = [f"    return np.array([{', '.join(components)}])"]
    elif form == "cfunc":
        head = ["def field(t, u, du, p):", *[f"    {name} = u[{i}]" for i, name in enumerate(names)]]
        tail = [f"    du[{i}] = {text}" for i, text in enumerate(components)]
    else:
        head = ["def field(t, y, args):", *[f"    {name} = y[{i}]" for i, name in enumerate(names)]]
        stacked = ", ".join(f"jnp.asarray({text}, dtype=y.dtype)" for text in components)
        tail = [f"    return jnp.stack([{stacked}])"]
    return FieldCode(form, "\n".join(head + body + tail) + "\n", n, count)


def derivatives_code(system, hessian: bool) -> FieldCode:
    """The source of ``derivatives(u, out, what)``, the body of a numba ``cfunc`` over pointers to
    float64 (`rkhp.taylor.generated.SIGNATURE`): at x = (u[0], ..., u[n-1]), ``what`` = 0 writes
    grad H(x) into out[0:n]; ``what`` = 1 writes grad H(x) and, with ``hessian``, Hess H(x) row by
    row into out[n:n + n^2] (each entry of the upper triangle computed once). H is read off the
    system's tape (:func:`hamiltonian_expression`; InputError where it holds a composite
    operation), differentiated by sympy, its common subexpressions named once per branch.
    ``operations`` counts those of the branch ``what`` = 1."""
    import sympy

    n = system.dim
    x = symbols_of(n)
    H = hamiltonian_expression(system)
    grad = [sympy.diff(H, v) for v in x]
    pairs = [(a, b) for a in range(n) for b in range(a, n)] if hessian else []
    second = [sympy.diff(grad[a], x[b]) for a, b in pairs]
    names = [str(v) for v in x]
    lines = ["def derivatives(u, out, what):", *[f"    {name} = u[{i}]" for i, name in enumerate(names)]]
    first_lines, first, _ = _printed(x, grad)
    both_lines, both, count = _printed(x, grad + second)
    lines += ["    if what == 0:", *[f"        {a} = {b}" for a, b in first_lines],
              *[f"        out[{k}] = {text}" for k, text in enumerate(first)],
              "    else:", *[f"        {a} = {b}" for a, b in both_lines],
              *[f"        out[{k}] = {text}" for k, text in enumerate(both[:n])]]
    for (a, b), text in zip(pairs, both[n:], strict=True):
        lines.append(f"        out[{n + n * a + b}] = {text}")
        if a != b:
            lines.append(f"        out[{n + n * b + a}] = out[{n + n * a + b}]")
    return FieldCode("derivatives", "\n".join(lines) + "\n", n, count)


POINTS = -1
"""``what`` = POINTS - q (q >= 1) asks the spray's code for X at q points at once (`spray_code`)."""


def spray_code(system) -> FieldCode:
    """The source of ``spray(u, out, what)``, the body of a numba ``cfunc`` over pointers to
    float64 (`rkhp.taylor.generated.SIGNATURE`): the frozen field of the Poisson spray X(y, p) =
    pi(y) p (docs/theory.md §9) at y = u[0:n], p = u[n:2n]. ``what`` = 1 writes X into out[0:n]
    and d_y X (n x n, by rows) into out[n:n + n^2]; ``what`` = 2 also pi(y) (= d_p X, by rows) into
    out[n + n^2:n + 2 n^2]; ``what`` = POINTS - q (q >= 1) writes X at the q points
    y_j = u[(2 + j) n:(3 + j) n] into out[j n:(j + 1) n] (j < q; p = u[n:2n]): the stages of a
    collocation in one call. pi from the system's family
    (:func:`poisson_expressions`; InputError where it has no symbolic form); each branch's common
    subexpressions named once. ``operations`` counts those of X at one point, ``branches`` those of
    X, of X with d_y X, and of the three."""
    import sympy

    n = system.dim
    y = symbols_of(n)
    p = tuple(sympy.Symbol(f"p{k + 1}", real=True) for k in range(n))
    pi = poisson_expressions(system)
    field = [sympy.Add(*[pi[a][b] * p[b] for b in range(n) if pi[a][b] != 0]) for a in range(n)]
    jacobian = [sympy.diff(field[a], y[b]) for a in range(n) for b in range(n)]
    matrix = [sympy.Integer(0) + pi[a][b] for a in range(n) for b in range(n)]  # entries 0 as sympy numbers
    names = [str(v) for v in y + p]
    lines = ["def spray(u, out, what):", *[f"    {name} = u[{k}]" for k, name in enumerate(names)]]
    printed = [_printed(y + p, exprs) for exprs in (field, field + jacobian, field + jacobian + matrix)]
    for what, (named, values, _) in enumerate(printed[1:], start=1):
        lines.append(f"    {'if' if what == 1 else 'elif'} what == {what}:")
        lines += [f"        {a} = {b}" for a, b in named]
        lines += [f"        out[{k}] = {text}" for k, text in enumerate(values)]
    named, values, _ = printed[0]
    lines += ["    else:", f"        for j in range({POINTS} - what):",
              *[f"            {name} = u[{2 * n + k} + {n} * j]" for k, name in enumerate(names[:n])]]
    lines += [f"            {a} = {b}" for a, b in named]
    lines += [f"            out[{k} + {n} * j] = {text}" for k, text in enumerate(values)]
    counts = tuple(operations for _, _, operations in printed)
    return FieldCode("spray", "\n".join(lines) + "\n", n, counts[0], counts)


def _namespace(form: str) -> dict:
    if form == "jax":
        import jax.numpy as jnp

        functions = SimpleNamespace(**{name: getattr(jnp, name) for name in ("exp", "log", "sin", "cos", "sqrt",
                                                                              "tan", "sinh", "cosh", "tanh")},
                                    atan=jnp.arctan, pi=math.pi, e=math.e)
        return {"math": functions, "jnp": jnp}
    return {"math": math, "np": np}


def compiled(code: FieldCode):
    """The function ``field`` that ``code.source`` defines (a Python function; the ``cfunc``
    form is then compiled by numba's ``cfunc``, the ``jax`` one traced by ``jax.jit``)."""
    namespace = _namespace(code.form)
    exec(compile(code.source, f"<field of {code.form}>", "exec"), namespace)  # noqa: S102 (checked tree)
    return namespace["field"]
