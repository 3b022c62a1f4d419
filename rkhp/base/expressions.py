"""The one safe reader of mathematical text: a whitelist over Python's `ast`, then sympy.

Every string that becomes mathematics (a spec file's Hamiltonian, Casimirs and Poisson-matrix
entries, a tableau entry) goes through :func:`parse_expression`. Nothing reaches `eval`,
`sympify` or `parse_expr`: the text is parsed by :func:`ast.parse` (which evaluates nothing), every
node is checked against the grammar below, sizes are bounded before any arithmetic, and the sympy
expression is built node by node from the checked tree.

Grammar (README "Expressions"):

- numbers: integer and decimal literals (read exactly: ``0.1`` is 1/10), no booleans, no complex;
- names: the variables the caller allows (``x1..xn``) and the constants ``pi`` and ``E``;
- operators: ``+ - * /``, powers ``**`` or ``^``, unary ``-`` and ``+``, parentheses;
- calls: the functions of :data:`FUNCTIONS` with one positional argument.

Limits (:class:`Limits`): the text's length, the depth of the expression tree, the number of its
nodes, the size of a constant exponent and the number of digits of any constant sub-expression
(so that ``10^10^10`` is refused at once instead of computed).
"""

from __future__ import annotations

import ast
import math
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from ..taylor.ops import FUNCTIONS as _TAPE_FUNCTIONS
from .bounds import float_or_infinity
from .errors import InputError

#: function name -> name of the sympy function it builds (documented in README "Expressions"):
#: the functions of the opcode table `rkhp.taylor.ops`, which the engine can differentiate
FUNCTIONS: dict[str, str] = {name: sympy_name for name, (sympy_name, _) in _TAPE_FUNCTIONS.items()}

#: constant name -> name of the sympy constant
CONSTANTS: dict[str, str] = {"pi": "pi", "E": "E"}


@dataclass(frozen=True)
class Limits:
    """Bounds checked before any work (README "Expressions").

    Attributes:
        length: characters of the text.
        depth: depth of the expression tree (nesting of operators, calls and parentheses).
        nodes: number of nodes of the expression tree.
        exponent: largest |constant exponent| of a power.
        digits: largest number of decimal digits of a constant sub-expression (a bound computed
            from the tree before anything is evaluated).
    """

    length: int = 20_000
    depth: int = 100
    nodes: int = 20_000
    exponent: int = 256
    digits: int = 2_000


LIMITS = Limits()
#: the limits of a tableau entry (a number such as ``(6 - sqrt(6))/10``; exact arithmetic with it
#: must stay cheap)
ENTRY_LIMITS = Limits(length=4_000, depth=12, nodes=200, exponent=16, digits=2_000)

_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_UNARY = {ast.USub: "-", ast.UAdd: "+"}

#: names of AST node types, as a user would call them, for the refusal message
_CONSTRUCTS = {
    "Attribute": "attribute access", "Lambda": "lambda", "ListComp": "comprehension",
    "SetComp": "comprehension", "DictComp": "comprehension", "GeneratorExp": "comprehension",
    "Subscript": "subscript", "BoolOp": "'and'/'or'", "Compare": "comparison",
    "IfExp": "conditional expression", "NamedExpr": "assignment", "Starred": "starred argument",
    "List": "list", "Tuple": "tuple", "Set": "set", "Dict": "dict", "JoinedStr": "f-string",
    "Await": "await", "Yield": "yield", "YieldFrom": "yield", "Slice": "slice",
}


def _quoted(text: str) -> str:
    return repr(text) if len(text) <= 60 else repr(text[:57] + "...")


def _refuse(where: str, text: str, reason: str):
    return InputError(f"{where}: cannot read {_quoted(text)}: {reason}")


#: a number token: a digit (or a point and a digit) not inside a name, up to the end of the literal
_NUMBER_TOKEN = re.compile(r"(?<![\w.])\.?[0-9](?:[eE][+-]|[\w.])*")
#: the numbers of the grammar: integers and decimals in ASCII digits, with an optional exponent
_DECIMAL = re.compile(r"([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")


def _lexical(text: str, where: str) -> None:
    """What Python's parser reads but the grammar does not have, refused before it is parsed: other
    characters than ASCII (Python reads a fullwidth x1 as x1), comments (`x1 # x2` would be x1)
    and numbers other than decimals (0x10, 1_000, 0o7, 1j)."""
    odd = next((c for c in text if ord(c) > 127), None)
    if odd is not None:
        raise _refuse(where, text, f"character U+{ord(odd):04X} is not allowed (ASCII only)")
    if "#" in text:
        raise _refuse(where, text, "'#' is not allowed (no comments)")
    bad = next((m.group() for m in _NUMBER_TOKEN.finditer(text) if not _DECIMAL.fullmatch(m.group())), None)
    if bad is not None:
        raise _refuse(where, text, f"{bad} is not a decimal number")


def _tree(text: str, where: str, limits: Limits) -> ast.expr:
    """The checked-size AST of `text` (`^` read as power)."""
    if not isinstance(text, str):
        raise InputError(f"{where}: expected an expression as a string, got {type(text).__name__}")
    if len(text) > limits.length:
        raise InputError(f"{where}: expression of {len(text)} characters; the limit is "
                         f"{limits.length}")
    if not text.strip():
        raise InputError(f"{where}: empty expression")
    if "\x00" in text:
        raise _refuse(where, text, "NUL character")
    _lexical(text, where)
    try:
        with warnings.catch_warnings():  # "invalid decimal literal" and the like: one line, ours
            warnings.simplefilter("ignore")
            return ast.parse(text.strip().replace("^", "**"), mode="eval").body
    except (SyntaxError, ValueError) as exc:
        reason = exc.msg if isinstance(exc, SyntaxError) else str(exc)
        raise _refuse(where, text, f"syntax error ({' '.join(reason.split())})") from None
    except (RecursionError, MemoryError):
        raise _refuse(where, text, f"nested deeper than {limits.depth}") from None


def _walk(root: ast.expr, text: str, where: str, names: frozenset, limits: Limits) -> None:
    """Check every node against the grammar, iteratively (no recursion on user input)."""
    stack = [(root, 1)]
    count = 0
    while stack:
        node, depth = stack.pop()
        count += 1
        if depth > limits.depth:
            raise _refuse(where, text, f"nested deeper than {limits.depth}")
        if count > limits.nodes:
            raise _refuse(where, text, f"more than {limits.nodes} terms")
        if isinstance(node, ast.Constant):
            value = node.value
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise _refuse(where, text, f"{type(value).__name__} literal {value!r} is not a number")
            if isinstance(value, float) and not math.isfinite(value):
                raise _refuse(where, text, "non-finite number")
        elif isinstance(node, ast.Name):
            if node.id not in names:
                raise _refuse(where, text, _unknown_name(node.id, names))
        elif isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            stack += [(node.left, depth + 1), (node.right, depth + 1)]
        elif isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            stack.append((node.operand, depth + 1))
        elif isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                called = node.func.id if isinstance(node.func, ast.Name) else "an expression"
                raise _refuse(where, text, f"call of {called} (functions: {', '.join(FUNCTIONS)})")
            if node.keywords or len(node.args) != 1:
                raise _refuse(where, text, f"{node.func.id} takes one positional argument")
            stack.append((node.args[0], depth + 1))
        else:
            kind = type(node).__name__
            what = _CONSTRUCTS.get(kind, f"operator or construct {kind}")
            if isinstance(node, ast.BinOp | ast.UnaryOp):
                what = f"operator {type(node.op).__name__}"
            raise _refuse(where, text, f"{what} is not allowed")


def _unknown_name(name: str, names: frozenset) -> str:
    if name.startswith("__") or name.endswith("__"):
        return f"name {name!r} is not allowed"
    variables = sorted(n for n in names if n not in CONSTANTS)
    allowed = f"{variables[0]}..{variables[-1]}" if len(variables) > 2 else ", ".join(variables)
    return f"unknown symbol {name!r} (allowed: {allowed + ', ' if allowed else ''}pi, E)"


class _Size(NamedTuple):
    """Of a constant sub-tree: a bound on log10 of its size (numerator and denominator) and an
    approximate value (float arithmetic; inf or nan where it overflows), for the limits."""

    digits: float
    value: float


_FLOAT_FUNCTIONS = {name: value for name, (_, value) in _TAPE_FUNCTIONS.items()}
_CONSTANT_VALUES = {"pi": math.pi, "E": math.e}


def _approx(function, *args) -> float:
    try:
        return float(function(*args))
    except (OverflowError, ZeroDivisionError, ValueError):
        return math.nan


def _sizes(node: ast.expr, text: str, where: str, limits: Limits, variables) -> None:
    """Bound the constant sub-trees before anything is evaluated: refuse a constant exponent
    above `limits.exponent` and a constant of more than `limits.digits` digits (sub-trees with a
    variable are left symbolic). Iterative post-order walk."""
    sizes: dict[int, _Size | None] = {}
    stack = [(node, False)]
    source = text.strip().replace("^", "**")
    while stack:
        current, done = stack.pop()
        children = _children(current)
        if not done:
            stack.append((current, True))
            stack += [(c, False) for c in children]
            continue
        sub = [sizes[id(c)] for c in children]
        is_power = isinstance(current, ast.BinOp) and isinstance(current.op, ast.Pow)
        if is_power and sub[1] is not None and not abs(sub[1].value) <= limits.exponent:
            raise _refuse(where, text, f"exponent larger than {limits.exponent}")
        if isinstance(current, ast.Name):
            size = None if current.id in variables else _Size(1.0, _CONSTANT_VALUES[current.id])
        elif isinstance(current, ast.Constant):
            literal = ast.get_source_segment(source, current) or ""
            size = _Size(_literal_digits(literal), float_or_infinity(current.value))
        elif None in sub:
            size = None
        elif isinstance(current, ast.Call):
            name = current.func.id
            value = _approx(_FLOAT_FUNCTIONS[name], sub[0].value)
            if not (math.isfinite(sub[0].value) and math.isfinite(value)):
                raise _refuse(where, text, f"the constant {name}(...) is not a real number (or not finite) "
                                           "in floating point")
            size = _Size(sub[0].digits + 1.0, value)
        elif isinstance(current, ast.UnaryOp):
            size = _Size(sub[0].digits, -sub[0].value if isinstance(current.op, ast.USub) else sub[0].value)
        else:
            size = _binary_size(current, sub)
        if size is not None and size.digits > limits.digits:
            raise _refuse(where, text, f"a constant with more than {limits.digits} digits")
        sizes[id(current)] = size


def _literal_digits(literal: str) -> float:
    """Decimal digits of the exact value of a number literal: its mantissa's digits plus the size
    of its exponent (``1e-400`` is read exactly as 10^-400: 401 digits)."""
    s = literal.replace("_", "").lower()
    if "e" not in s or s.startswith(("0x", "0o", "0b")):
        return float(max(len(s), 1))
    mantissa, exponent = s.split("e", 1)
    if len(exponent.lstrip("+-")) > 9:
        return math.inf
    return float(len(mantissa) + abs(int(exponent)))


def _binary_size(node: ast.BinOp, sub) -> _Size:
    """The size of a binary operation of two constants (its exponent already checked)."""
    (a, va), (b, vb) = sub
    op = type(node.op)
    if op is ast.Pow:
        return _Size(a * max(abs(vb), 1.0) + b + 1.0, _approx(pow, va, vb))
    value = {ast.Add: lambda: va + vb, ast.Sub: lambda: va - vb, ast.Mult: lambda: va * vb,
             ast.Div: lambda: va / vb}[op]
    return _Size(a + b + 1.0, _approx(value))


def _children(node: ast.expr) -> list[ast.expr]:
    if isinstance(node, ast.BinOp):
        return [node.left, node.right]
    if isinstance(node, ast.UnaryOp):
        return [node.operand]
    if isinstance(node, ast.Call):
        return list(node.args)
    return []


def _build(root: ast.expr, text: str, symbols: dict):
    """The sympy expression of a checked tree (iterative post-order; literals read exactly)."""
    import sympy

    source = text.strip().replace("^", "**")
    functions = {name: getattr(sympy, target) for name, target in FUNCTIONS.items()}
    values: dict[int, object] = {}
    stack = [(root, False)]
    while stack:
        node, done = stack.pop()
        children = _children(node)
        if not done:
            stack.append((node, True))
            stack += [(c, False) for c in children]
            continue
        args = [values.pop(id(c)) for c in children]
        if isinstance(node, ast.Constant):
            literal = ast.get_source_segment(source, node) or repr(node.value)
            value = sympy.Integer(node.value) if isinstance(node.value, int) else \
                sympy.Rational(literal.replace("_", ""))
        elif isinstance(node, ast.Name):
            value = symbols[node.id]
        elif isinstance(node, ast.Call):
            value = functions[node.func.id](args[0])
        elif isinstance(node, ast.UnaryOp):
            value = -args[0] if isinstance(node.op, ast.USub) else args[0]
        else:
            a, b = args
            op = type(node.op)
            value = (a + b if op is ast.Add else a - b if op is ast.Sub else a * b if op is ast.Mult
                     else a / b if op is ast.Div else a ** b)
        values[id(node)] = value
    return values[id(root)]


def parse_expression(text, variables: Sequence[str] = (), *, where: str = "expression",
                     limits: Limits = LIMITS):
    """The sympy expression of `text` in the given variable names (see the module docstring).

    Raises InputError with one line naming `where`, the text and the reason for anything outside
    the grammar or the limits; non-finite results (``1/0``, ``log(0)``) are refused too.
    """
    names = frozenset(variables) | frozenset(CONSTANTS)
    root = _tree(text, where, limits)
    _walk(root, text, where, names, limits)
    _sizes(root, text, where, limits, frozenset(variables))
    import sympy  # only for text that passed every check

    symbols = {name: sympy.Symbol(name, real=True) for name in variables}
    symbols.update({name: getattr(sympy, target) for name, target in CONSTANTS.items()})
    try:
        expr = _build(root, text, symbols)
    except (ZeroDivisionError, ValueError, TypeError, OverflowError) as exc:
        raise _refuse(where, text, " ".join(str(exc).split()) or type(exc).__name__) from None
    if expr.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        raise _refuse(where, text, "not finite (division by zero or a pole)")
    return expr


def variable_names(n: int) -> tuple[str, ...]:
    """The names x1..xn of the state variables of a system of dimension n."""
    return tuple(f"x{i}" for i in range(1, n + 1))
