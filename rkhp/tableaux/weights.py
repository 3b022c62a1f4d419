"""Elementary weights a(t) of every tree up to order N, in one pass, in several arithmetics.

docs/theory.md §2: Phi_i(b) = 1, Phi_i(b[t1..tn]) = prod_k (A Phi(tk))_i, a(t) = b . Phi(t). The trees are
built as in the enumeration of :mod:`rkhp.trees.rooted`: t = b[c1, *rest] from its largest child c1 and
r = b[rest], so that

    Phi(t) = (A Phi(c1)) * Phi(r)        (elementwise; Phi(b) = 1)

and every tree costs one elementwise product of two stored vectors, plus one product by A when
it is the largest child of some tree of order < N (its order is below N - 1); at order N,
a(b[c1]) = (b^T A) Phi(c1) needs no product by A. A :class:`TreePlan` holds the indices (c1, r) of every tree;
the arithmetics work on whole blocks of trees of one order at once:

- ``float``: numpy float64;
- ``digits``: fixed point, values scaled by 2^bits as Python integers (60+ digits);
- ``exact``: Fractions, or elements of an algebraic number field (sympy) for radicals.

:func:`symbolic_weights` gives a(t) as polynomials in symbols a_i_j, b_i.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache

import numpy as np

from ..base.bounds import float_or_infinity
from ..base.errors import InputError
from ..trees.rooted import LEAF, Tree, check_order, count_trees, trees_up_to
from .tableau import Tableau, as_sympy, is_exact, to_fraction

# ----------------------------------------------------------------------------- the plan


@dataclass(frozen=True, eq=False)
class TreePlan:
    """All trees of T up to ``max_order``, grouped by order, with the (c1, r) index of each.

    ``first[k]`` is the index of the largest child of tree k, ``rest[k]`` the index of the tree
    b[other children] (the leaf, index 0, when there are none). ``starts[n]`` is the index of the
    first tree of order n (``starts[max_order + 1]`` the number of trees). ``in_t0`` marks T_0.
    """

    max_order: int
    trees: tuple[Tree, ...]
    starts: tuple[int, ...]
    first: np.ndarray
    rest: np.ndarray
    in_t0: np.ndarray
    gamma: tuple[int, ...]
    sigma: tuple[int, ...]
    gamma_float: np.ndarray
    sigma_float: np.ndarray

    def block(self, n: int) -> slice:
        """Indices of the trees of order n."""
        return slice(self.starts[n], self.starts[n + 1])

    def index(self, t: Tree) -> int:
        return self._index[t.key]

    @property
    def _index(self) -> dict[bytes, int]:
        return _key_index(self)


@lru_cache(maxsize=2)
def _key_index(plan: TreePlan) -> dict[bytes, int]:
    return {t.key: k for k, t in enumerate(plan.trees)}


@lru_cache(maxsize=2)
def tree_plan(max_order: int) -> TreePlan:
    """The plan of all trees up to ``max_order`` (cached: the two most recent)."""
    check_order(max_order)
    trees = tuple(trees_up_to(max_order))
    # t = b[c1, *rest]: c1 = t.children[0] and t.rest are trees of this same enumeration
    index = {t.key: k for k, t in enumerate(trees)}
    first = [0] + [index[t.children[0].key] for t in trees[1:]]
    rest = [0] + [index[t.rest.key] for t in trees[1:]]
    n = len(trees)
    starts = [0, 0]
    for m in range(1, max_order + 1):
        starts.append(starts[-1] + count_trees(m))
    first_ = np.array(first, dtype=np.intp)
    rest_ = np.array(rest, dtype=np.intp)
    # T_0 (docs/theory.md §1): no vertex has a leaf as its only child. t = b[c1, rest] has all its
    # children in T_0 when c1 is in T_0 and r's children are; only b[b] then fails at its root.
    kids_ok = np.ones(n, dtype=bool)
    in_t0 = np.ones(n, dtype=bool)
    for m in range(2, max_order + 1):
        blk = slice(starts[m], starts[m + 1])
        kids_ok[blk] = in_t0[first_[blk]] & kids_ok[rest_[blk]]
        in_t0[blk] = kids_ok[blk]
        if m == 2:
            in_t0[blk] = False  # b[b]
    gamma = tuple(t.gamma for t in trees)
    sigma = tuple(t.sigma for t in trees)
    return TreePlan(max_order, trees, tuple(starts), first_, rest_, in_t0, gamma, sigma,
                    np.array(gamma, dtype=float), np.array(sigma, dtype=float))


# ----------------------------------------------------------------------------- arithmetics


MAX_PRECISION_DIGITS = 2000
"""Most decimal digits of a fixed-point verification."""


class FloatArithmetic:
    """float64 numpy arrays."""

    name = "float"
    exact = False
    #: relative rounding unit of the inputs and of each operation
    unit = 2.0 ** -52

    def matrix(self, tableau: Tableau):
        return tableau.A_float, tableau.b_float

    def empty(self, rows: int, s: int):
        return np.empty((rows, s))

    one = 1.0

    def hadamard(self, X, Y):
        return X * Y

    def matmul(self, P, A):
        return P @ A.T

    def dot(self, P, b):
        return P @ b

    def left(self, b, A):
        """b^T A."""
        return b @ A

    def residuals(self, a, gammas):
        """r(t) = gamma(t) a(t) - 1 for a block (gammas as floats or ints)."""
        return np.asarray(gammas, dtype=float) * a - 1.0

    def to_floats(self, r):
        return np.asarray(r, dtype=float)


class FixedPointArithmetic:
    """Fixed point: a value x is the Python integer round(x 2^bits); products are shifted back.

    With ``digits`` decimal digits, bits = ceil(digits log2 10) + 32 guard bits, so rounding in
    the pass stays far below 10^-digits. The rows of A are used sparsely (Feagin's 35 x 35 matrix
    has 325 non-zero entries).
    """

    exact = False

    def __init__(self, digits: int):
        self.digits = digits
        self.bits = math.ceil(digits * math.log2(10)) + 32
        self.name = f"{digits} digits"
        self.unit = 10.0 ** (1 - digits)

    def _fixed(self, x) -> int:
        return round(to_fraction(x, self.bits + 64) * (1 << self.bits))

    def matrix(self, tableau: Tableau):
        A = np.array([[self._fixed(x) for x in row] for row in tableau.A], dtype=object)
        b = np.array([self._fixed(x) for x in tableau.b], dtype=object)
        self._rows = [(i, np.nonzero(A[i] != 0)[0]) for i in range(len(A))]
        return A, b

    def empty(self, rows: int, s: int):
        return np.zeros((rows, s), dtype=object)

    @property
    def one(self):
        return 1 << self.bits

    def hadamard(self, X, Y):
        return (X * Y) >> self.bits

    def matmul(self, P, A):
        out = np.zeros(P.shape, dtype=object)
        for i, cols in self._rows:
            if len(cols) == 1:
                out[:, i] = (P[:, cols[0]] * A[i, cols[0]]) >> self.bits
            elif len(cols):
                out[:, i] = P[:, cols].dot(A[i, cols]) >> self.bits
        return out

    def dot(self, P, b):
        return P.dot(b) >> self.bits

    def left(self, b, A):
        return b.dot(A) >> self.bits

    def residuals(self, a, gammas):
        return np.array(gammas, dtype=object) * a - (1 << self.bits)

    def to_floats(self, r):
        """Float values of fixed-point integers (or of Fractions of them)."""
        scale = Fraction(1, 1 << self.bits)
        return np.array([math.ldexp(float(x), -self.bits) if isinstance(x, int)
                         and abs(x) < 1 << 1000 else float_or_infinity(Fraction(x) * scale) for x in r])


class ExactArithmetic:
    """Exact: Fractions when every entry is rational, else an algebraic number field (sympy)."""

    name = "exact"
    exact = True
    unit = 0.0

    def __init__(self, tableau: Tableau):
        entries = tableau.entries()
        if all(isinstance(x, Fraction) for x in entries):
            self.field = None
            self.one = Fraction(1)
        else:
            self.field = number_field(entries)
            self.one = self.field.one

    def _value(self, x):
        if self.field is None:
            return x
        try:
            return self.field.from_sympy(as_sympy(x))
        except Exception as exc:  # sympy's failures have no common base class
            raise NoNumberField(f"{x} is not in {self.field} ({type(exc).__name__})") from None

    def matrix(self, tableau: Tableau):
        A = np.array([[self._value(x) for x in row] for row in tableau.A], dtype=object)
        b = np.array([self._value(x) for x in tableau.b], dtype=object)
        return A, b

    def empty(self, rows: int, s: int):
        return np.empty((rows, s), dtype=object)

    def hadamard(self, X, Y):
        return X * Y

    def matmul(self, P, A):
        return P.dot(A.T)

    def dot(self, P, b):
        return P.dot(b)

    def left(self, b, A):
        return b.dot(A)

    def residuals(self, a, gammas):
        if self.field is None:
            return np.array(gammas, dtype=object) * a - 1
        K = self.field
        return np.array([x * K.convert(g) - K.one for g, x in zip(gammas, a, strict=True)],
                        dtype=object)

    def is_zero(self, x) -> bool:
        return x == 0 if self.field is None else self.field.is_zero(x)

    def to_sympy(self, x):
        import sympy

        return sympy.Rational(x.numerator, x.denominator) if self.field is None \
            else self.field.to_sympy(x)

    def to_floats(self, r):
        """Float values for display (+-inf beyond the float range: the decisions are exact)."""
        if self.field is None:
            return np.array([float_or_infinity(x) for x in r])
        return np.array([float_or_infinity(self.to_sympy(x).evalf(30)) for x in r])

    def scale(self, x, w: Fraction):
        """x * w for a rational w."""
        if self.field is None:
            return x * w
        from sympy import QQ

        return x * self.field.convert(QQ(w.numerator, w.denominator))


class NoNumberField(InputError):
    """The entries' number field is out of reach (too large, or sympy cannot build it);
    ``reason`` says why."""

    def __init__(self, reason: str, message: str | None = None):
        super().__init__(message or reason)
        self.reason = reason


#: Largest degree over Q of a number field built for exact verification (product of the
#: generators' degrees); beyond it the entries are verified at a number of digits. Exact
#: arithmetic slows down steeply with the degree (measured, 4-stage tableaux: Q(sqrt 3, cos pi/18),
#: degree 12, 2.4 s CPU; Q(2^(1/3), sqrt 2, sqrt 3), degree 12, 4.6 s; four square roots, degree 16,
#: 22 s), so degree 12 is the most that stays within seconds (docs/input.md).
MAX_FIELD_DEGREE = 12


def field_generators(expr) -> set:
    """The algebraic generators of an exact entry: its irrational powers (``sqrt(3)``) and its
    function values (``cos(pi/18)``, algebraic of degree 6)."""
    import sympy

    return ({p for p in expr.atoms(sympy.Pow) if not p.exp.is_Integer}
            | {f for f in expr.atoms(sympy.Function) if not f.is_Rational})


def degree_bound(generator) -> int | None:
    """A cheap upper bound on the degree over Q of a generator, where one is known without its
    minimal polynomial (whose degree-N computation takes minutes for N in the thousands): q for a
    radical a^(p/q) of a rational a; phi(4q) for cos or sin of a rational multiple p/q of pi."""
    import sympy

    if isinstance(generator, sympy.Pow) and generator.exp.is_Rational and generator.base.is_Rational:
        return int(generator.exp.q)
    if isinstance(generator, sympy.cos | sympy.sin):
        ratio = generator.args[0] / sympy.pi
        if ratio.is_Rational:
            return int(sympy.totient(4 * ratio.q))
    return None


#: a generator whose degree bound exceeds this is refused without its minimal polynomial (it
#: would be refused anyway unless the bound is far from the degree)
MAX_DEGREE_BOUND = 4 * MAX_FIELD_DEGREE


def number_field(values):
    """Q(generators of the values), None for Q itself; NoNumberField when its degree exceeds
    MAX_FIELD_DEGREE or sympy cannot build it."""
    irrational = [x for x in values if not isinstance(x, Fraction)]
    if not irrational:  # Q: no sympy (it costs ~0.5 s to import)
        return None
    import sympy
    from sympy import QQ

    generators = sorted({g for x in irrational for g in field_generators(x)}, key=sympy.default_sort_key)
    if not generators:
        return None
    for g in generators:
        bound = degree_bound(g)
        if bound is not None and bound > MAX_DEGREE_BOUND:
            raise NoNumberField(f"their number field has degree up to {bound} > {MAX_FIELD_DEGREE} ({g})")
    try:
        degree = math.prod(sympy.minimal_polynomial(g).as_poly().degree() for g in generators)
    except Exception as exc:  # sympy's failures have no common base class
        raise NoNumberField(f"no minimal polynomial for the entries ({type(exc).__name__})") from None
    if degree > MAX_FIELD_DEGREE:
        raise NoNumberField(f"their number field has degree up to {degree} > {MAX_FIELD_DEGREE}")
    try:
        return QQ.algebraic_field(*generators)
    except Exception as exc:
        raise NoNumberField(f"sympy cannot build Q({', '.join(map(str, generators))}) "
                            f"({type(exc).__name__})") from None


def arithmetic_for(tableau: Tableau, precision):
    """The arithmetic for a precision: "float", "exact" or a number of decimal digits."""
    if precision == "float":
        return FloatArithmetic()
    if precision == "exact":
        if not tableau.is_exact:
            bad = next(x for x in tableau.entries() if not is_exact(x))
            raise InputError(f"{tableau.source or tableau.name}: exact precision needs exact "
                             f"entries, but {bad.text if hasattr(bad, 'text') else bad} is given "
                             f"to {getattr(bad, 'digits', 17)} digits (use a number of digits)")
        try:
            arithmetic = ExactArithmetic(tableau)
            arithmetic.matrix(tableau)  # every entry in the field, or NoNumberField now
        except NoNumberField as exc:
            raise NoNumberField(exc.reason, f"{tableau.source or tableau.name}: no exact verification: "
                                f"{exc.reason} (use a number of digits)") from None
        return arithmetic
    if isinstance(precision, int) and not isinstance(precision, bool):
        if not 16 <= precision <= MAX_PRECISION_DIGITS:
            raise InputError(f"precision must be float, exact or 16..{MAX_PRECISION_DIGITS} digits, got {precision}")
        return FixedPointArithmetic(precision)
    raise InputError(f"precision must be float, exact or a number of digits, got {precision!r}")


# ----------------------------------------------------------------------------- the pass


def weights_by_order(tableau: Tableau, max_order: int, arithmetic=None):
    """Yield (n, block, a) for n = 1..max_order: the weights a(t) of the trees plan.block(n).

    One pass (module docstring): each tree's stage vector comes from two stored vectors, and A is
    applied once per tree of order < max_order - 1. The trees b[c1] of the last order need no
    A Phi(c1): a(b[c1]) = (b^T A) Phi(c1). ``arithmetic`` defaults to float64.
    """
    arithmetic = arithmetic or FloatArithmetic()
    plan = tree_plan(max_order)
    A, b = arithmetic.matrix(tableau)
    bA = arithmetic.left(b, A)
    s = tableau.stages
    N = max_order
    Phi = arithmetic.empty(max(plan.starts[N], 1), s)  # orders < N
    AP = arithmetic.empty(max(plan.starts[N - 1], 1), s)  # orders < N - 1
    Phi[0] = arithmetic.one
    if N >= 3:
        AP[0:1] = arithmetic.matmul(Phi[0:1], A)
    yield 1, plan.block(1), arithmetic.dot(Phi[0:1], b)
    first, rest = plan.first, plan.rest
    for n in range(2, N):
        blk = plan.block(n)
        phi = arithmetic.hadamard(AP[first[blk]], Phi[rest[blk]])
        Phi[blk] = phi
        if n < N - 1:
            AP[blk] = arithmetic.matmul(phi, A)
        yield n, blk, arithmetic.dot(phi, b)
    if N >= 2:
        blk = plan.block(N)
        f, r = first[blk], rest[blk]
        single = r == 0  # t = b[c1], |c1| = N - 1
        a = arithmetic.dot(Phi[f[single]], bA)
        out = np.empty(len(f), dtype=a.dtype)
        out[single] = a
        if not single.all():
            multi = ~single
            out[multi] = arithmetic.dot(arithmetic.hadamard(AP[f[multi]], Phi[r[multi]]), b)
        yield N, blk, out


def elementary_weights(tableau: Tableau, max_order: int, precision="float") -> dict[Tree, object]:
    """a(t) for every tree of T with |t| <= max_order (float, exact, or a number of digits).

    Exact values are Fractions or sympy numbers; digits give Fractions with denominator 2^bits.
    """
    arithmetic = arithmetic_for(tableau, precision)
    plan = tree_plan(max_order)
    out = {}
    for _, blk, a in weights_by_order(tableau, max_order, arithmetic):
        for t, x in zip(plan.trees[blk], a, strict=True):
            out[t] = _plain(arithmetic, x)
    return out


def _plain(arithmetic, x):
    if isinstance(arithmetic, FixedPointArithmetic):
        return Fraction(int(x), 1 << arithmetic.bits)
    if isinstance(arithmetic, ExactArithmetic):
        return x if arithmetic.field is None else arithmetic.to_sympy(x)
    return float(x)


# ----------------------------------------------------------------------------- symbolic


def tableau_symbols(s: int, explicit: bool = True):
    """Symbols of a generic s-stage tableau: (A, b, c) with A[i][j] = a_{i+1}_{j+1} (0 above the
    diagonal when explicit), b[i] = b_{i+1}, c[i] = c_{i+1} (1-based names as in the paper)."""
    import sympy

    A = [[sympy.Symbol(f"a_{i + 1}_{j + 1}") if (j < i or not explicit) else sympy.Integer(0)
          for j in range(s)] for i in range(s)]
    b = [sympy.Symbol(f"b_{i + 1}") for i in range(s)]
    c = [sympy.Symbol(f"c_{i + 1}") for i in range(s)]
    return A, b, c


def symbolic_weights(trees, s: int, explicit: bool = True, c_symbols: bool = False) -> dict:
    """a(t) for each tree as a sympy polynomial in the a_i_j and b_i of :func:`tableau_symbols`.

    Leaves are folded into c_i (Butcher's form, docs/theory.md §2): c_i is the row sum of A, or the symbol
    c_i when ``c_symbols`` (then the row-sum conditions c_i = sum_j a_ij are left to the caller).
    Stage vectors are computed once per subtree, in a sparse polynomial ring.
    """
    import sympy
    from sympy.polys.rings import ring

    A, b, c = tableau_symbols(s, explicit)
    names = [x for row in A for x in row if x.is_Symbol] + b + (c if c_symbols else [])
    R, *gens = ring(names, sympy.QQ)
    value = dict(zip(names, gens, strict=True))
    Ar = [[value.get(x, R.zero) for x in row] for row in A]
    br = [value[x] for x in b]
    cr = [value[x] for x in c] if c_symbols else [sum(row, R.zero) for row in Ar]
    memo: dict[Tree, list] = {}
    memo_a: dict[Tree, list] = {LEAF: cr}

    def A_phi(t: Tree) -> list:
        if t not in memo_a:
            phi = stage(t)
            memo_a[t] = [sum((a * p for a, p in zip(row, phi, strict=True) if a), R.zero)
                         for row in Ar]
        return memo_a[t]

    def stage(t: Tree) -> list:
        if t not in memo:
            out = [R.one] * s
            for child in t.children:
                out = [x * y for x, y in zip(out, A_phi(child), strict=True)]
            memo[t] = out
        return memo[t]

    return {t: sum((bi * p for bi, p in zip(br, stage(t), strict=True)), R.zero).as_expr()
            for t in trees}
