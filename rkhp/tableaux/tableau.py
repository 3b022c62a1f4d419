"""Butcher tableaux: the value, its entries (exact or at the digits given), its kind.

Paper §5.2: an RKHP method is defined by a Runge–Kutta tableau (A, b); the stage abscissae are
the row sums c_i = sum_j a_ij (docs/theory.md §2), so a ``c`` given in a file is only compared with them.

Entries keep the precision they were given with (see :func:`parse_entry`):

- integers, rationals ``"11/27"`` and decimals of at most 15 significant digits (``0.25``,
  ``"-0.8"``) are exact: :class:`fractions.Fraction`;
- radicals such as ``"sqrt(3)/4"`` or ``"(6 - sqrt(6))/10"`` are exact: sympy expressions;
- decimals with more than 15 significant digits (the 60-digit published coefficients, or a float
  such as ``0.1111111111111111``) are approximations known to the digits given:
  :class:`GivenDecimal`, an ``mpmath.mpf`` that remembers its text and digits.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property

import mpmath

from ..base.bounds import MAX_DECIMAL_DIGITS, MAX_DECIMAL_EXPONENT
from ..base.errors import InputError
from ..base.exact_text import fraction_latex
from ..base.expressions import ENTRY_LIMITS, parse_expression

#: Decimals with at most this many significant digits are read as exact decimals.
EXACT_DECIMAL_DIGITS = 15

_DECIMAL = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_RATIONAL = re.compile(r"^[+-]?\d+\s*/\s*[+-]?\d+$")


class GivenDecimal(mpmath.mpf):
    """A decimal coefficient known to ``digits`` significant digits (an ``mpmath.mpf``).

    ``text`` is the decimal as given, so that files round-trip digit for digit; arithmetic on it
    gives plain ``mpf`` values at the current mpmath precision.
    """

    def __new__(cls, text: str, digits: int):
        value = mpmath.mpf.__new__(cls, text, dps=digits + 5)
        value.text = text
        value.digits = digits
        return value

    def as_fraction(self) -> Fraction:
        """The given decimal as an exact rational (its digits, not its binary approximation)."""
        return Fraction(self.text)


def significant_digits(text: str) -> int:
    """Significant digits of a decimal literal, trailing zeros included (0 for a zero)."""
    mantissa = re.split(r"[eE]", text.strip().lstrip("+-"))[0].replace(".", "")
    stripped = mantissa.lstrip("0")
    return len(stripped) if stripped.strip("0") else 0


def parse_entry(value, where: str = "entry"):
    """One tableau entry from a file or from Python: Fraction, sympy expression or GivenDecimal.

    ``where`` names the entry in error messages (file and field). Raises InputError for
    booleans, non-numeric text, non-finite values and expressions that are not real numbers.
    """
    if isinstance(value, (Fraction, GivenDecimal)):
        return value
    if isinstance(value, bool) or value is None:
        raise InputError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, int):
        if value.bit_length() > 3.33 * MAX_DECIMAL_DIGITS:
            raise InputError(f"{where}: an integer of more than {MAX_DECIMAL_DIGITS} digits")
        return Fraction(value)
    if type(value).__module__ == "numpy":
        value = value.item()
        return parse_entry(value, where)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise InputError(f"{where}: non-finite value {value!r}")
        return _decimal(repr(value))
    if isinstance(value, mpmath.mpf):
        if not mpmath.isfinite(value):
            raise InputError(f"{where}: non-finite value {value}")
        return _decimal(mpmath.nstr(value, mpmath.mp.dps, min_fixed=-1, max_fixed=-1))
    if isinstance(value, str):
        return _parse_text(value, where)
    if type(value).__module__.startswith("sympy"):
        return _exact_expression(value, where, str(value))
    raise InputError(f"{where}: expected a number or a string, got {type(value).__name__}")


def _decimal(text: str):
    digits = significant_digits(text)
    if digits <= EXACT_DECIMAL_DIGITS:
        return Fraction(text)
    return GivenDecimal(text, digits)


def _check_decimal(s: str, where: str) -> None:
    """Bound a decimal's digits and exponent before any exact arithmetic (``1e999999999`` would
    take hours to read exactly; docs/input.md)."""
    mantissa, _, exponent = s.lower().partition("e")
    if len(mantissa) > MAX_DECIMAL_DIGITS + 2:
        raise InputError(f"{where}: a decimal of more than {MAX_DECIMAL_DIGITS} digits")
    if exponent and (len(exponent.lstrip("+-")) > 6 or abs(int(exponent)) > MAX_DECIMAL_EXPONENT):
        raise InputError(f"{where}: the exponent of {s[:40]!r} is beyond +-{MAX_DECIMAL_EXPONENT}")


#: entries read from expression texts in this process, by text (a value is immutable and depends on
#: the text alone; a refused text is never kept): sympy's radsimp of a nested radical costs tens of
#: milliseconds, and the compositions repeat their coefficients (tj8's are products of tj4's)
_EXPRESSION_ENTRIES: dict[str, object] = {}
MAX_KNOWN_EXPRESSIONS = 1024


def _parse_text(text: str, where: str):
    s = text.strip()
    if _DECIMAL.match(s):
        _check_decimal(s, where)
        return _decimal(s)
    if _RATIONAL.match(s):
        if len(s) > 2 * MAX_DECIMAL_DIGITS + 3:
            raise InputError(f"{where}: a fraction of more than {MAX_DECIMAL_DIGITS} digits")
        num, den = (int(x) for x in s.split("/"))
        if den == 0:
            raise InputError(f"{where}: division by zero in {text!r}")
        return Fraction(num, den)
    if s.lower().lstrip("+-") in ("nan", "inf", "infinity"):
        raise InputError(f"{where}: non-finite value {text!r}")
    known = _EXPRESSION_ENTRIES.get(s)
    if known is not None:
        return known
    value = _exact_expression(parse_expression(s, (), where=where, limits=ENTRY_LIMITS), where, text)
    if len(_EXPRESSION_ENTRIES) < MAX_KNOWN_EXPRESSIONS:
        _EXPRESSION_ENTRIES[s] = value
    return value


def _exact_expression(expr, where: str, text: str):
    import sympy

    expr = sympy.nsimplify(expr) if expr.has(sympy.Float) else expr
    if not expr.is_number or expr.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        raise InputError(f"{where}: not a finite number: {text!r}")
    if expr.is_real is not True or expr.is_algebraic is not True:
        raise InputError(f"{where}: not a real algebraic number: {text!r}")
    expr = sympy.radsimp(expr)
    if expr.is_Rational:
        return Fraction(int(expr.p), int(expr.q))
    return expr


def as_sympy(x):
    """An exact entry (Fraction or sympy number) as a sympy number."""
    import sympy

    return sympy.Rational(x.numerator, x.denominator) if isinstance(x, Fraction) else x


def is_exact(x) -> bool:
    """Whether an entry is exact (a rational or a sympy algebraic number)."""
    return not isinstance(x, mpmath.mpf)


def is_zero(x) -> bool:
    """Whether an entry is exactly zero."""
    if isinstance(x, (Fraction, mpmath.mpf)):
        return x == 0
    return bool(x.is_zero)


def entry_text(x) -> str:
    """The text that reads back as the same entry: ``p/q``, ``sqrt(3)/4`` or the given digits."""
    if isinstance(x, Fraction):
        return str(x)
    if isinstance(x, GivenDecimal):
        return x.text
    if isinstance(x, mpmath.mpf):  # a computed value (a row sum): mpmath's current digits
        return mpmath.nstr(x, mpmath.mp.dps, min_fixed=-5, max_fixed=mpmath.mp.dps)
    return str(x)


def _magnitude(x) -> str:
    """A short text of a (huge) entry: six significant digits and an exponent."""
    try:
        if isinstance(x, Fraction):
            return mpmath.nstr(mpmath.mpf(x.numerator) / x.denominator, 6)
        return mpmath.nstr(mpmath.mpf(str(x)) if isinstance(x, GivenDecimal) else x, 6)
    except (TypeError, ValueError):
        return str(x)[:40]


def to_float(x) -> float:
    """float64 value of an entry; InputError when it is beyond the float range (the float paths,
    integration and float verification, cannot represent it; exact verification can)."""
    try:
        value = float(x) if isinstance(x, (Fraction, mpmath.mpf)) else float(x.evalf(20))
    except OverflowError:
        value = math.inf
    if not math.isfinite(value):
        raise InputError(f"the entry {_magnitude(x)} is beyond the float range (|x| > 1.8e308): "
                         "float arithmetic cannot represent it (verify with --precision exact)")
    return value


def to_fraction(x, bits: int) -> Fraction:
    """An exact rational within 2^-bits (relative) of an entry; exact for rationals and decimals."""
    if isinstance(x, Fraction):
        return x
    if isinstance(x, GivenDecimal):
        return x.as_fraction()
    if isinstance(x, mpmath.mpf):
        sign, man, exp, _ = x._mpf_  # x = (-1)^sign man 2^exp
        value = Fraction(int(man)) * Fraction(2) ** exp
        return -value if sign else value
    import sympy

    value = sympy.Rational(x.evalf(int(bits * 0.30103) + 10))  # the binary value, exactly
    return Fraction(int(value.p), int(value.q))


def _sum(values):
    """Exact sum of entries when all are exact (sympy only if needed), else an mpf sum."""
    if all(isinstance(v, Fraction) for v in values):
        return sum(values, Fraction(0))
    if all(is_exact(v) for v in values):
        import sympy

        total = sympy.radsimp(sympy.nsimplify(sum(as_sympy(v) for v in values)))
        return Fraction(int(total.p), int(total.q)) if total.is_Rational else total
    digits = max(getattr(v, "digits", 17) for v in values) + 10
    total = sum((to_fraction(v, 4 * digits) for v in values), Fraction(0))
    with mpmath.workdps(digits):
        return mpmath.mpf(total.numerator) / total.denominator


def _readonly(array):
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class Tableau:
    """A Runge–Kutta tableau (A, b) with its metadata (paper §5.2; docs/theory.md §2).

    Attributes:
        name: the method's name (a built-in name, or the file's).
        A: s rows of s entries; b: s entries (see :func:`parse_entry` for the entry types).
        c: the row sums of A, which the RKHP conditions use.
        c_given: the abscissae given in the file, or None; :meth:`c_mismatch` compares them.
        aliases, reference, notes: metadata; claimed_order, claimed_degenerate_order,
        claimed_symmetric_order: the orders the source claims in each class (None when it claims
        none).
    """

    name: str
    A: tuple
    b: tuple
    c_given: tuple | None = None
    aliases: tuple[str, ...] = ()
    reference: str = ""
    notes: str = ""
    claimed_order: int | None = None
    claimed_degenerate_order: int | None = None
    claimed_symmetric_order: int | None = None
    source: str = field(default="", compare=False)

    def __post_init__(self):
        where = self.source or self.name
        self._read_entries(where)
        s = len(self.A)
        if s == 0:
            raise InputError(f"{where}: A is empty")
        for i, row in enumerate(self.A):
            if len(row) != s:
                raise InputError(f"{where}: A is not square (row {i + 1} has {len(row)} entries, "
                                 f"A has {s} rows)")
        if len(self.b) != s:
            raise InputError(f"{where}: b has {len(self.b)} entries, A has {s} rows")
        if self.c_given is not None and len(self.c_given) != s:
            raise InputError(f"{where}: c has {len(self.c_given)} entries, A has {s} rows")
        for what, value in (("order", self.claimed_order),
                            ("degenerate_order", self.claimed_degenerate_order),
                            ("symmetric_order", self.claimed_symmetric_order)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                      or value < 1):
                raise InputError(f"{where}: claimed {what} must be a positive integer, "
                                 f"got {value!r}")

    def _read_entries(self, where: str) -> None:
        """Entries given as plain Python or numpy numbers or text (``Tableau(name, A, b)`` called
        directly) read as :meth:`from_arrays` reads them (`parse_entry`); InputError otherwise."""
        def ready(x):  # the entry types, computed mpmath values included (kept at their precision)
            return isinstance(x, (Fraction, mpmath.mpf)) or type(x).__module__.startswith("sympy")

        def entry_rows(value, label):
            if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__iter__"):
                raise InputError(f"{where}: {label} must be a list, got {type(value).__name__}")
            return list(value)

        A = [entry_rows(r, f"row {i + 1} of A") for i, r in enumerate(entry_rows(self.A, "A"))]
        b = entry_rows(self.b, "b")
        c = None if self.c_given is None else entry_rows(self.c_given, "c")
        if all(ready(x) for r in A for x in r) and all(ready(x) for x in b) and all(ready(x) for x in c or ()):
            if not (isinstance(self.A, tuple) and all(isinstance(r, tuple) for r in self.A)
                    and isinstance(self.b, tuple)):
                object.__setattr__(self, "A", tuple(tuple(r) for r in A))
                object.__setattr__(self, "b", tuple(b))
            return
        object.__setattr__(self, "A", tuple(tuple(parse_entry(x, f"{where}: A[{i + 1}][{j + 1}]")
                                                  for j, x in enumerate(r)) for i, r in enumerate(A)))
        object.__setattr__(self, "b", tuple(parse_entry(x, f"{where}: b[{i + 1}]") for i, x in enumerate(b)))
        if c is not None:
            object.__setattr__(self, "c_given", tuple(parse_entry(x, f"{where}: c[{i + 1}]")
                                                      for i, x in enumerate(c)))

    @classmethod
    def from_arrays(cls, A, b, name: str = "custom", c=None, **metadata) -> Tableau:
        """A tableau from numbers (lists, numpy arrays, strings, Fractions, sympy values)."""
        rows = [list(r) for r in A]
        A_ = tuple(tuple(parse_entry(x, f"{name}: A[{i + 1}][{j + 1}]") for j, x in enumerate(r))
                   for i, r in enumerate(rows))
        b_ = tuple(parse_entry(x, f"{name}: b[{i + 1}]") for i, x in enumerate(b))
        c_ = None if c is None else tuple(parse_entry(x, f"{name}: c[{i + 1}]")
                                          for i, x in enumerate(c))
        return cls(name=name, A=A_, b=b_, c_given=c_, **metadata)

    # ------------------------------------------------------------------ structure

    @property
    def claims(self) -> dict[str, int | None]:
        """The claimed order per class of conditions (general, degenerate, symmetric)."""
        return {"general": self.claimed_order, "degenerate": self.claimed_degenerate_order,
                "symmetric": self.claimed_symmetric_order}

    @property
    def stages(self) -> int:
        return len(self.b)

    @cached_property
    def kind(self) -> str:
        """"explicit" (A strictly lower triangular), "diagonally implicit" or "implicit"."""
        s = self.stages
        if any(not is_zero(self.A[i][j]) for i in range(s) for j in range(i + 1, s)):
            return "implicit"
        if any(not is_zero(self.A[i][i]) for i in range(s)):
            return "diagonally implicit"
        return "explicit"

    @property
    def is_explicit(self) -> bool:
        return self.kind == "explicit"

    @cached_property
    def c(self) -> tuple:
        """Row sums c_i = sum_j a_ij (docs/theory.md §2)."""
        return tuple(_sum(list(row)) for row in self.A)

    def entries(self):
        """Every entry of A and b."""
        return [x for row in self.A for x in row] + list(self.b)

    @cached_property
    def is_exact(self) -> bool:
        """Whether every entry of A and b is exact."""
        return all(is_exact(x) for x in self.entries())

    @cached_property
    def is_rational(self) -> bool:
        return all(isinstance(x, Fraction) for x in self.entries())

    @cached_property
    def digits(self) -> int | None:
        """Fewest significant digits among the inexact entries (None when all are exact)."""
        given = [x.digits if isinstance(x, GivenDecimal) else 17
                 for x in self.entries() if not is_exact(x)]
        return min(given) if given else None

    def c_mismatch(self) -> list[tuple[int, float]]:
        """Stages (0-based) whose given c differs from the row sum, with the difference.

        Exact values are compared exactly; otherwise a difference above the rounding of the
        given digits, s * 10^(1-digits) * (1 + sum_j |a_ij|), counts.
        """
        if self.c_given is None:
            return []
        out = []
        for i, (given, row_sum) in enumerate(zip(self.c_given, self.c, strict=True)):
            if is_exact(given) and is_exact(row_sum):
                diff = _sum([given, -row_sum])
                if not is_zero(diff):
                    out.append((i, to_float(diff)))
                continue
            digits = min(getattr(x, "digits", 17) for x in (*self.A[i], given)
                         if not is_exact(x))
            scale = 1 + sum(abs(to_float(x)) for x in self.A[i])
            diff = float(to_fraction(given, 400) - to_fraction(row_sum, 400))
            if abs(diff) > self.stages * 10.0 ** (1 - digits) * scale:
                out.append((i, diff))
        return out

    # ------------------------------------------------------------------ float views

    @cached_property
    def A_float(self):
        import numpy as np

        return _readonly(np.array([[to_float(x) for x in row] for row in self.A], dtype=float))

    @cached_property
    def b_float(self):
        import numpy as np

        return _readonly(np.array([to_float(x) for x in self.b], dtype=float))

    @cached_property
    def c_float(self):
        import numpy as np

        return _readonly(np.array([to_float(x) for x in self.c], dtype=float))

    def describe(self) -> str:
        """``rk4 (4 stages, explicit)``."""
        return f"{self.name} ({self.stages} stages, {self.kind})"

    # ------------------------------------------------------------------ display

    def blank_above_diagonal(self) -> bool:
        """Whether the Butcher array leaves the (zero) entries on and above the diagonal blank."""
        return self.is_explicit

    def __str__(self) -> str:
        """The Butcher array c | A / b with the entries as given (exact, or their digits)."""
        return self.describe() + "\n" + butcher_text(self, entry_text)

    def to_latex(self) -> str:
        """The Butcher array as a LaTeX ``array`` (math mode; needs no package)."""
        return butcher_latex(self)

    def _repr_latex_(self) -> str:
        return "$$" + self.to_latex() + "$$"


# ----------------------------------------------------------------------------- display


def entry_decimal(x, digits: int = 12) -> str:
    """An entry rounded to ``digits`` significant digits (``0.333333333333``; ``0`` for zero)."""
    if is_zero(x):
        return "0"
    value = to_fraction(x, int(digits * 3.33) + 64)
    with mpmath.workdps(digits + 10):
        text = mpmath.nstr(mpmath.mpf(value.numerator) / value.denominator, digits,
                           min_fixed=-5, max_fixed=digits + 1)
    return text[:-2] if text.endswith(".0") else text


def entry_latex(x) -> str:
    """LaTeX of an entry: ``\\frac{1}{2}``, ``-\\frac{\\sqrt{3}}{6}``, or the given digits."""
    if isinstance(x, Fraction):
        return fraction_latex(x)
    if isinstance(x, mpmath.mpf):
        return entry_text(x)
    import sympy

    return sympy.latex(x)


def butcher_cells(tableau: Tableau, fmt) -> list[list[str]]:
    """Rows [c_i, a_i1, ..., a_is] then ["", b_1, ..., b_s], entries as ``fmt(x)``; entries on
    and above the diagonal of an explicit tableau are "" (the usual blank)."""
    blank = tableau.blank_above_diagonal()
    rows = [[fmt(tableau.c[i])] + ["" if blank and j >= i else fmt(x) for j, x in enumerate(row)]
            for i, row in enumerate(tableau.A)]
    return rows + [[""] + [fmt(x) for x in tableau.b]]


def butcher_text(tableau: Tableau, fmt, gap: int = 2) -> str:
    """The Butcher array as aligned text lines (c | A, a rule, then | b)."""
    rows = butcher_cells(tableau, fmt)
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    sep = " " * gap

    def line(cells):
        left = cells[0].ljust(widths[0])
        right = sep.join(c.ljust(w) for c, w in zip(cells[1:], widths[1:], strict=True))
        return f"{left} │ {right}".rstrip()

    rule = "─" * (widths[0] + 1) + "┼" + "─" * (sum(widths[1:]) + gap * (len(widths) - 2) + 1)
    return "\n".join([line(r) for r in rows[:-1]] + [rule, line(rows[-1])])


def butcher_latex(tableau: Tableau) -> str:
    """``\\begin{array}{c|ccc} ... \\end{array}``: c | A, a rule, then b (paper §5.2)."""
    rows = butcher_cells(tableau, entry_latex)
    spec = "c|" + "c" * tableau.stages
    body = [" & ".join(r) + " \\\\" for r in rows[:-1]] + ["\\hline", " & ".join(rows[-1])]
    return "\\begin{array}{" + spec + "}\n" + "\n".join(body) + "\n\\end{array}"
