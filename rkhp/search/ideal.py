"""The order conditions of a search as polynomials with integer coefficients, and their text form.

For an explicit tableau with ``S`` stages the unknowns are c_2..c_S, the a_ij with 2 <= j < i,
and b_1..b_S: the first column of A is replaced by the row sums, a_i1 = c_i - sum_{j=2}^{i-1} a_ij
(c_1 = 0). This invertible affine change of unknowns leaves the set of solutions in bijection with
the tableaux, and it removes the a_i1 from every condition but through c_i (row 1 of A is zero, so
Phi_1(t) = 0 for every tree t other than the single vertex, and a_i1 only ever multiplies such a
Phi_1(t) or 1): the polynomials are sparser. Implicit tableaux keep the unknowns a_ij, b_i.

Each generator is the residual sum_k w_k (gamma(t_k) a(t_k) - 1) of one condition
(:mod:`rkhp.search.system`), times the positive integer that makes its coefficients coprime
integers.

Linear elimination (:meth:`ConditionIdeal.reduced`): every b_i enters linearly, and (explicit
tableaux) b_1 only through sum b_i = 1, b_2 only through the trees whose root has leaves only
(Phi_2(t) = c_2^k for those, 0 for the others). For a variable x of degree one, write each
generator containing it f_j = P_j x + Q_j; the consecutive combinations
(P_{j+1}/h) f_j - (P_j/h) f_{j+1}, h = gcd(P_j, P_{j+1}), do not contain x, and with the generators
free of x they generate an ideal J contained in the ideal I of the conditions. So 1 in J proves
1 in I; the converse is not claimed (the proof falls back on I when J is proper). On degenerate
order 6 with 5 stages, eliminating b_1, b_2 turns Singular's basis over Q from none in 180 s of
CPU into 0.5 s.

Polynomials travel as text in the usual notation (``3*c2^2*b2 - 1``), written and read
here without any expression evaluator: a term is an optional sign, a rational coefficient and
powers of known variable names joined by ``*``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ..base.errors import InputError
from .system import ResidualSystem

#: Variables eliminated before the basis that decides (fastest measured: degenerate order 7 with
#: 6 stages, basis [1] over Q in 23 s with b_1..b_3 eliminated, none in 20 s modulo 32003 with
#: b_1, b_2 only) and before the cofactors (symmetric order 6 with 4 stages: liftstd 2.4 s with
#: b_1, b_2 eliminated, none in 60 s with b_1..b_3).
DECISION_ELIMINATION = ("b1", "b2", "b3")
CERTIFICATE_ELIMINATION = ("b1", "b2")


@dataclass(frozen=True)
class ConditionIdeal:
    """The generators of the ideal of a search problem.

    Attributes:
        stages, order, cls, implicit: the problem.
        variables: the unknowns' names, in the ring's order.
        generators: one polynomial per condition with a nonzero residual polynomial, as text.
        substitution: how the unknowns relate to the tableau (text).
    """

    stages: int
    order: int
    cls: str
    implicit: bool
    variables: tuple[str, ...]
    generators: tuple[str, ...]
    substitution: str
    eliminated: tuple[str, ...] = ()

    def reduced(self, names=CERTIFICATE_ELIMINATION) -> ConditionIdeal:
        """The ideal J of the module docstring, ``names`` eliminated in turn while they enter
        linearly (explicit tableaux only; ``self`` when nothing can be eliminated)."""
        if self.implicit or self.eliminated:
            return self
        R = self.ring()
        polys = self.polynomials()
        done = []
        for name in names:
            if name not in self.variables:
                break
            out = eliminate_linear(polys, R.gens[self.variables.index(name)])
            if out is None:
                break
            polys = out
            done.append(name)
        if not done:
            return self
        return ConditionIdeal(self.stages, self.order, self.cls, self.implicit, self.variables,
                              tuple(polynomial_text(p, self.variables) for p in polys),
                              self.substitution, tuple(done))

    def ring(self):
        """The sympy polynomial ring QQ[variables] (grevlex) and its generators' polynomials."""
        return polynomial_ring(self.variables)

    def polynomials(self):
        """The generators as elements of :meth:`ring`."""
        R = self.ring()
        return [parse_polynomial(text, R) for text in self.generators]


def _name(prefix: str, i: int, j: int | None, stages: int) -> str:
    if j is None:
        return f"{prefix}{i}"
    return f"{prefix}{i}{j}" if stages < 10 else f"{prefix}{i}_{j}"


def problem_variables(system: ResidualSystem) -> tuple[list[str], str]:
    """The unknowns' names (1-based) and the substitution text (module docstring)."""
    s = system.stages
    bs = [_name("b", i + 1, None, s) for i in range(s)]
    if system.implicit:
        return [_name("a", i + 1, j + 1, s) for i, j in system.pattern] + bs, "none: a_ij and b_i"
    cs = [_name("c", i + 1, None, s) for i in range(1, s)]
    inner = [_name("a", i + 1, j + 1, s) for i, j in system.pattern if j >= 1]
    return cs + inner + bs, "a_i1 = c_i - sum_{j=2}^{i-1} a_ij for i >= 2 (c_1 = 0)"


def polynomial_ring(variables):
    """QQ[variables] with grevlex order (sympy's sparse polynomials)."""
    from sympy import QQ
    from sympy.polys.orderings import grevlex
    from sympy.polys.rings import ring

    return ring(",".join(variables), QQ, grevlex)[0]


def _tableau_unknowns(system: ResidualSystem, R, variables):
    """The system's unknowns x = (a over the pattern, b) as polynomials of R."""
    gens = dict(zip(variables, R.gens, strict=True))
    s = system.stages
    if system.implicit:
        return np.array(list(R.gens), dtype=object)
    values = []
    for i, j in system.pattern:
        if j == 0:
            rest = sum((gens[_name("a", i + 1, k + 1, s)] for k in range(1, i)), R.zero)
            values.append(gens[_name("c", i + 1, None, s)] - rest)
        else:
            values.append(gens[_name("a", i + 1, j + 1, s)])
    values += [gens[_name("b", i + 1, None, s)] for i in range(s)]
    return np.array(values, dtype=object)


def integer_primitive(p):
    """p times the positive rational that makes its coefficients coprime integers (p != 0)."""
    _, q = p.clear_denoms()
    return q.primitive()[1]


def eliminate_linear(polys, x):
    """Generators free of ``x`` (module docstring), or None when x has degree > 1 somewhere."""
    free, linear = [], []
    for p in polys:
        d = p.degree(x)
        if d > 1:
            return None
        (linear if d == 1 else free).append(p)
    combined = []
    for f, g in zip(linear, linear[1:]):
        pf, pg = f.diff(x), g.diff(x)
        h = pf.gcd(pg)
        new = pg.exquo(h) * f - pf.exquo(h) * g
        if new:
            combined.append(integer_primitive(new))
    return free + combined


def condition_ideal(system: ResidualSystem) -> ConditionIdeal:
    """The ideal of ``system`` (module docstring), generators in condition order."""
    variables, substitution = problem_variables(system)
    R = polynomial_ring(variables)
    x = _tableau_unknowns(system, R, variables)
    residuals, _ = system.residuals(x, jacobian=False)
    gens = [integer_primitive(R(p)) for p in residuals if R(p) != 0]
    return ConditionIdeal(system.stages, system.order, system.cls, system.implicit,
                          tuple(variables), tuple(polynomial_text(p, variables) for p in gens),
                          substitution)


# ----------------------------------------------------------------------------- text


def _coefficient_text(c: Fraction) -> str:
    return str(c.numerator) if c.denominator == 1 else f"{c.numerator}/{c.denominator}"


def polynomial_text(p, variables) -> str:
    """``p`` as text, terms by decreasing monomial in the ring's order (``0`` for zero)."""
    if not p:
        return "0"
    parts = []
    for monom, coeff in p.terms():
        c = Fraction(int(coeff.numerator), int(coeff.denominator))
        powers = [v if e == 1 else f"{v}^{e}" for v, e in zip(variables, monom, strict=True) if e]
        mag = abs(c)
        factors = ([] if mag == 1 and powers else [_coefficient_text(mag)]) + powers
        sign = "-" if c < 0 else "+"
        parts.append((sign, "*".join(factors)))
    head_sign, head = parts[0]
    text = ("-" if head_sign == "-" else "") + head
    return text + "".join(f" {sign} {body}" for sign, body in parts[1:])


_TERM = re.compile(r"\s*([+-]?)\s*([^+\-\s][^+\-]*)")
_FACTOR = re.compile(r"^(?:(\d+)(?:/(\d+))?|([A-Za-z][A-Za-z0-9_]*)(?:\^(\d+))?)$")
#: Largest exponent accepted in a polynomial's text.
MAX_EXPONENT = 200


def parse_polynomial(text: str, R):
    """The polynomial of ``R`` written in ``text`` (``polynomial_text`` or Singular's output).

    Raises InputError on anything else than sums of products of rationals and powers of R's
    variables (no evaluation: the text is matched token by token).
    """
    names = {str(g): k for k, g in enumerate(R.gens)}
    n = len(names)
    terms: dict[tuple[int, ...], Fraction] = {}
    pos = 0
    text = text.strip()
    if text == "0":
        return R.zero
    while pos < len(text):
        m = _TERM.match(text, pos)
        if m is None or (pos > 0 and not m.group(1)):
            raise InputError(f"not a polynomial term at character {pos}: {text[pos:pos + 30]!r}")
        pos = m.end()
        coeff = Fraction(-1 if m.group(1) == "-" else 1)
        expo = [0] * n
        for factor in m.group(2).strip().split("*"):
            f = _FACTOR.match(factor.strip())
            if f is None:
                raise InputError(f"not a number or a power of a variable: {factor.strip()!r}")
            if f.group(1) is not None:
                den = int(f.group(2) or 1)
                if den == 0:
                    raise InputError("zero denominator in a coefficient")
                coeff *= Fraction(int(f.group(1)), den)
                continue
            if f.group(3) not in names:
                raise InputError(f"unknown variable {f.group(3)!r}")
            e = int(f.group(4) or 1)
            if e > MAX_EXPONENT:
                raise InputError(f"exponent {e} above {MAX_EXPONENT}")
            expo[names[f.group(3)]] += e
        key = tuple(expo)
        terms[key] = terms.get(key, Fraction(0)) + coeff
    dom = R.domain
    return R.from_dict({k: dom.convert(c) for k, c in terms.items() if c})
