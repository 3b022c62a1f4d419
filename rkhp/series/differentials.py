"""Elementary differentials F(t) on truncated Taylor jets, exactly (docs/theory.md §5 and §8).

F(b) = H and F(b[t1..tk])(x) = d^k_p f(x, 0)[grad F(t1)(x), ..., grad F(tk)(x)] with
f = H o alpha (paper §5.1, Theorem "superconvergence"). Every function of x is held as its Taylor
polynomial at the base point, truncated at the degree that the trees still need: a subtree s of a
tree of order <= N sits at depth <= N - |s|, so F(s) is needed to degree N - |s| and H to degree
N - 1. Coefficients are residues modulo a prime below 2^31 (numpy int64, vectorised over a batch
of random instances) or exact Python integers (``p=None``, object arrays).

The birealisations are the registry's (`rkhp.systems.families`, `rkhp.systems.core`): one
source of the formulas for the float engine and for this exact path.

- :func:`general_values`: any registered family's base alpha composed with any realisation's
  shift, the very programs that record the engine's tapes, run here on :class:`ExactJet` values
  (truncated jets in (x - x0, p) mod p) with exact functions (:data:`EXACT_FUNCTIONS`: exp and
  phi(K) x as their truncated series; the constants of the programs are read exactly, 0.5 as
  1/2). Why an evaluation of its own: the engine evaluates in float64 (with guards, a closed form
  for so(3)*), while the relations need exact residues of the same Taylor coefficients.
- :func:`constant_pi_values`: the constant family's base alpha = x - pi p / 2 in closed form,
  d^k_p f(x,0)[v1..vk] = (-1/2)^k D^k H(x)[pi v1, ..., pi vk] (fast for large batches); the
  factor (-1/2)^(|t|-1) is common to all trees of one order and is left out (integers stay
  integers, relations are unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from functools import cache
from itertools import combinations_with_replacement
from math import comb, factorial
from types import SimpleNamespace

import numpy as np

from ..base.modular import to_residue
from ..systems.core import realisation as realisation_kind
from ..systems.families import CONSTANT, LIE_POISSON, LOG_CANONICAL, SO3, LieAlgebra
from ..systems.families import family as poisson_family
from ..trees.rooted import Tree

# ----------------------------------------------------------------------------- monomial bases


@dataclass(frozen=True, eq=False)
class MonomialBasis:
    """Monomials in ``nvars`` variables of degree <= ``degree``, graded (degree 0 first).

    A polynomial truncated at degree m is the prefix of length ``sizes[m]`` of its coefficient
    vector, so truncation is slicing.
    """

    nvars: int
    degree: int
    exponents: np.ndarray  # (M, nvars)
    sizes: tuple[int, ...]  # sizes[m] = number of monomials of degree <= m
    index: dict


@cache
def monomial_basis(nvars: int, degree: int) -> MonomialBasis:
    exps = []
    for d in range(degree + 1):
        for combo in combinations_with_replacement(range(nvars), d):
            e = [0] * nvars
            for v in combo:
                e[v] += 1
            exps.append(tuple(e))
    exps.sort(key=lambda e: (sum(e), tuple(-x for x in e)))
    sizes = tuple(comb(m + nvars, nvars) for m in range(degree + 1))
    index = {e: i for i, e in enumerate(exps)}
    return MonomialBasis(nvars, degree, np.array(exps, dtype=np.int64), sizes, index)


@cache
def _derivative_table(basis: MonomialBasis, var: int) -> tuple[np.ndarray, np.ndarray]:
    """(source index, factor) for each monomial of degree <= degree - 1: d/dx_var of sum c_e x^e."""
    src, fac = [], []
    for e in basis.exponents[: basis.sizes[basis.degree - 1]] if basis.degree else []:
        up = list(int(x) for x in e)
        up[var] += 1
        src.append(basis.index[tuple(up)])
        fac.append(up[var])
    return np.array(src, dtype=np.int64), np.array(fac, dtype=np.int64)


@cache
def _product_table(basis: MonomialBasis, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ia, ib, starts): the pairs of monomials with degree sum <= m, grouped by their product.

    ``np.add.reduceat(a[ia] * b[ib], starts)`` is the product truncated at degree m.
    """
    size = basis.sizes[m]
    exps = basis.exponents[:size]
    deg = exps.sum(axis=1)
    ia, ib, out = [], [], []
    for i in range(size):
        j = np.nonzero(deg <= m - deg[i])[0]
        prod = exps[j] + exps[i]
        ia.append(np.full(j.size, i))
        ib.append(j)
        out.append([basis.index[tuple(map(int, e))] for e in prod])
    ia, ib, out = np.concatenate(ia), np.concatenate(ib), np.concatenate(out)
    order = np.argsort(out, kind="stable")
    starts = np.searchsorted(out[order], np.arange(size))
    return ia[order], ib[order], starts


class JetRing:
    """Truncated polynomials with coefficients mod p (int64) or exact integers (p None).

    Arrays have shape (M, batch): one column per random instance.
    """

    def __init__(self, basis: MonomialBasis, p: int | None):
        if p is not None and not 2 < p < 2**31:
            raise ValueError("the modulus must be a prime below 2^31")
        self.basis = basis
        self.p = p
        self.dtype = np.int64 if p is not None else object

    def reduce(self, a: np.ndarray) -> np.ndarray:
        return a % self.p if self.p is not None else a

    def size(self, m: int) -> int:
        return self.basis.sizes[m]

    def mul(self, a: np.ndarray, b: np.ndarray, m: int) -> np.ndarray:
        """The product of a and b truncated at degree m."""
        if m == 0:
            return self.reduce(a[:1] * b[:1])
        ia, ib, starts = _product_table(self.basis, m)
        return self.reduce(np.add.reduceat(self.reduce(a[ia] * b[ib]), starts, axis=0))

    def derivative(self, a: np.ndarray, var: int, m: int) -> np.ndarray:
        """d/dx_var of a, truncated at degree m (a must hold degree m + 1)."""
        src, fac = _derivative_table(self.basis, var)
        size = self.basis.sizes[m]
        return self.reduce(a[src[:size]] * fac[:size, None])


# ----------------------------------------------------------------------------- elementary differentials


def _multisets(nvars: int, k: int):
    return list(combinations_with_replacement(range(nvars), k))


def _sorted_insert(J: tuple[int, ...], i: int) -> tuple[int, ...]:
    return tuple(sorted(J + (i,)))


def elementary_differentials(trees, max_order: int, ring: JetRing, partials, transform,
                             nspace: int | None = None, jets: bool = False):
    """F(t) for the trees given (and all their subtrees), at the base point or as jets.

    ``partials(J, m)``: d_p^J f(x, 0) for a sorted index tuple J as a jet truncated at degree m
    (shape (size(m), batch)); ``transform(grad, m)``: the vectors that fill the slots from the
    gradient list of a child (identity for the general form, pi grad for constant pi).
    ``nspace``: the number of space variables x (the first ones of the ring; default all of them):
    further variables, such as the step h of a graded series (docs/theory.md §11), are
    parameters that derivatives leave alone. Returns a dict tree -> array (batch,) of F(t) at the
    base point, or with ``jets`` the jet of F(t) truncated at degree max_order - |t|.
    """
    nvars = ring.basis.nvars if nspace is None else nspace
    table_of: dict[Tree, np.ndarray] = {}
    slots: dict[Tree, list[np.ndarray]] = {}

    def need(t: Tree) -> int:
        return max_order - t.order

    def jet(t: Tree) -> np.ndarray:
        if t in table_of:
            return table_of[t]
        m = need(t)
        if not t.children:
            value = partials((), m)
        else:
            k = len(t.children)
            table = {J: partials(J, m) for J in _multisets(nvars, k)}
            for pos in range(k - 1, -1, -1):
                u = vectors(t.children[pos], m)
                table = {
                    J: _jet_sum(ring, [ring.mul(u[i], table[_sorted_insert(J, i)], m) for i in range(nvars)])
                    for J in _multisets(nvars, pos)
                }
            value = table[()]
        table_of[t] = value
        return value

    def vectors(s: Tree, m: int) -> list[np.ndarray]:
        if s not in slots:
            f = jet(s)
            grad = [ring.derivative(f, i, need(s) - 1) for i in range(nvars)]
            slots[s] = transform(grad, need(s) - 1)
        size = ring.size(m)
        return [v[:size] for v in slots[s]]

    return {t: jet(t) if jets else jet(t)[0] for t in trees}


def _derivatives(ring: JetRing, K: np.ndarray):
    """dK(J): the partial derivative d^J K (J a sorted index tuple) truncated at degree - |J|, cached."""
    cache: dict[tuple[int, ...], np.ndarray] = {(): K}
    degree = ring.basis.degree

    def dK(J):
        if J not in cache:
            cache[J] = ring.derivative(dK(J[:-1]), J[-1], degree - len(J))
        return cache[J]

    return dK


def _exponent(J: tuple[int, ...], dim: int) -> tuple[tuple[int, ...], int]:
    """The multi-index of a sorted index tuple and its factorial: (0, 2, 2) -> ((1, 0, 2), 2)."""
    e = [0] * dim
    for j in J:
        e[j] += 1
    scale = 1
    for c in e:
        scale *= factorial(c)
    return tuple(e), scale


def _index_tuple(exponent) -> tuple[int, ...]:
    """The sorted index tuple of a multi-index: (1, 0, 2) -> (0, 2, 2)."""
    return tuple(v for v in range(len(exponent)) for _ in range(int(exponent[v])))


def _jet_sum(ring: JetRing, terms: list[np.ndarray]) -> np.ndarray:
    total = terms[0].copy()
    for x in terms[1:]:
        total += x
    return ring.reduce(total)


# ----------------------------------------------------------------------------- random instances


def _random_residues(rng: np.random.Generator, shape, p: int | None, bound: int):
    """Uniform residues mod p, or integers in [-bound, bound] (exact mode)."""
    if p is not None:
        return rng.integers(0, p, size=shape, dtype=np.int64)
    return np.array(rng.integers(-bound, bound + 1, size=shape), dtype=object)


def constant_pi_values(trees, max_order: int, dim: int, batch: int, rng: np.random.Generator,
                       p: int | None, bound: int = 3) -> dict[Tree, np.ndarray]:
    """F(t)(0) * (-2)^(|t|-1) on ``batch`` random systems with constant pi in dimension ``dim``.

    Each instance: a random antisymmetric pi and a random polynomial H of degree max_order - 1
    (its Taylor jet at 0); residues mod p, or integers in [-bound, bound] when p is None.
    """
    basis = monomial_basis(dim, max(max_order - 1, 0))
    H = _random_residues(rng, (basis.sizes[-1], batch), p, bound)
    upper = _random_residues(rng, (dim, dim, batch), p, bound)
    return constant_pi_jets(trees, max_order, H, upper - upper.transpose(1, 0, 2), p)


def constant_pi_jets(trees, max_order: int, H: np.ndarray, pi: np.ndarray, p: int | None) -> dict[Tree, np.ndarray]:
    """F(t)(0) * (-2)^(|t|-1) for given Hamiltonians and constant Poisson matrices.

    ``H``: (M, batch) coefficients of polynomials of degree max_order - 1 over
    ``monomial_basis(dim, max_order - 1)``; ``pi``: (dim, dim, batch) antisymmetric matrices.
    With alpha = x - pi p / 2 the slots take (-1/2) pi grad; the factor (-1/2)^(|t|-1), common to
    the trees of one order, is left out: this is :func:`constant_matrix_jets` with D = pi.
    """
    basis = monomial_basis(pi.shape[0], max(max_order - 1, 0))
    return constant_matrix_jets(trees, max_order, H, pi, p, basis)


def constant_matrix_jets(trees, max_order: int, K: np.ndarray, D: np.ndarray, p: int | None,
                         basis: MonomialBasis, jets: bool = False) -> dict[Tree, np.ndarray]:
    """F(t) for alpha(x, p) = x + D p with a constant matrix D (dim, dim, batch) per instance.

    Then d_p^k f(x, 0)[v1..vk] = D^k K(x)[D v1, ..., D vk]: the partials are derivatives of K and
    the slots take D grad. ``K``: (M, batch) coefficients over ``basis``, whose first dim variables
    are x (further ones are parameters, e.g. h; docs/theory.md §11). D = -pi/2 is the symmetric
    constant-pi realisation, D = Q - pi/2 (Q symmetric) the shifted one (§4).
    """
    dim = D.shape[0]
    ring = JetRing(basis, p)
    D = ring.reduce(D)
    dK = _derivatives(ring, ring.reduce(K))

    def constant_partials(J, m):
        return dK(J)[: ring.size(m)]

    def transform(grad, m):
        return [_jet_sum(ring, [ring.reduce(D[i, j][None, :] * grad[j]) for j in range(dim)]) for i in range(dim)]

    return elementary_differentials(trees, max_order, ring, constant_partials, transform, dim, jets)


class PolynomialShift:
    """The realisation alpha(x, p) = x + A(p), A a polynomial map in p alone (no x), modulo a prime.

    f(x, p) = sum_beta d^beta K(x) A(p)^beta / beta!, so d_p^J f(x, 0) = sum_beta c_J,beta d^beta K(x)
    with c_J,beta = J! [p^J] A(p)^beta / beta!, scalars per instance: the partials are combinations
    of derivatives of K. ``A``: dim arrays (M_p, batch) over ``monomial_basis(dim, degree)`` in the
    variables p, without constant term; the powers A^beta/beta! are computed once. Covers the
    quartic realisation A(p) = -pi p / 2 + grad K(p) (degenerate, not symmetric; docs/theory.md §8)
    and its non-degenerate variants with a quadratic K.
    """

    def __init__(self, A: list[np.ndarray], p: int, degree: int):
        self.dim = len(A)
        self.p = p
        self.A = A
        pring = JetRing(monomial_basis(self.dim, max(degree, 1)), p)
        self.pbasis = pbasis = pring.basis
        top = pbasis.degree
        one = np.zeros((pbasis.sizes[top], A[0].shape[1]), dtype=np.int64)
        one[0] = 1
        powers = [one]
        for idx in range(1, pbasis.sizes[top]):
            e = tuple(int(x) for x in pbasis.exponents[idx])
            v = next(i for i in range(self.dim) if e[i])
            lower = list(e)
            lower[v] -= 1
            prev = powers[pbasis.index[tuple(lower)]]
            powers.append(pring.reduce(pring.mul(prev, pring.reduce(A[v]), top) * pow(e[v], -1, p)))
        self.powers = np.array(powers)  # (monomials beta, monomials of p, batch)
        self.betas = [_index_tuple(e) for e in pbasis.exponents]

    def jets(self, trees, max_order: int, K: np.ndarray, basis: MonomialBasis, jets: bool = False):
        """F(t) of the Hamiltonian K (coefficients over ``basis``, whose first dim variables are x)."""
        dim, pbasis = self.dim, self.pbasis
        ring = JetRing(basis, self.p)
        K = ring.reduce(K)
        dK = _derivatives(ring, K)
        pcache: dict[tuple[int, ...], np.ndarray] = {(): K}

        def tree_partials(J, m):
            if J not in pcache:
                pexp, scale = _exponent(J, dim)
                size = ring.size(basis.degree - len(J))
                stop = pbasis.sizes[len(J)]
                coeffs = self.powers[1:stop, pbasis.index[pexp]]
                derivs = np.array([dK(self.betas[idx])[:size] for idx in range(1, stop)])
                total = ring.reduce(ring.reduce(derivs * coeffs[:, None, :]).sum(axis=0))
                pcache[J] = ring.reduce(total * scale)
            return pcache[J][: ring.size(m)]

        return elementary_differentials(trees, max_order, ring, tree_partials, lambda grad, m: grad, dim, jets)


@dataclass(eq=False)
class RandomRealisations:
    """Random birealisations alpha(x, p) = x + A(p), beta(x, p) = x + A(p) + pi p with constant pi,
    one per column of a batch, modulo a prime: the generic instances of a class (docs/theory.md §11).

    A(p) = D p + grad K(p): symmetric class, D = -pi/2 and K = 0 (alpha = x - pi p / 2); degenerate,
    D = -pi/2 and a random K of degrees 3..N (the quartic kind, not symmetric); general, a random K
    of degrees 2..N (its quadratic part is the shifted kind, D = Q - pi/2). With ``linear``, K keeps
    its quadratic part only (general) or vanishes. Symmetric and linear instances draw pi (and Q)
    per column; the others share one realisation (random modulo p, hence generic but for a set of
    probability O(1/p)), so that A's powers are computed once.
    """

    p: int
    pi: np.ndarray  # (n, n, columns or 1)
    D: np.ndarray  # (n, n, columns or 1): d_p A(0)
    shift: PolynomialShift | None  # None when A(p) = D p

    @classmethod
    def of_class(cls, kind: str, n: int, N: int, ncols: int, rng: np.random.Generator, p: int,
                 linear: bool = False) -> RandomRealisations:
        shared = not (kind == "symmetric" or linear)
        cols = 1 if shared else ncols
        upper = rng.integers(0, p, size=(n, n, cols), dtype=np.int64)
        pi = (upper - upper.transpose(1, 0, 2)) % p
        D = pi * to_residue(Fraction(-1, 2), p) % p
        if kind == "symmetric" or (linear and kind == "degenerate"):
            return cls(p, pi, D, None)
        if linear:
            q = rng.integers(0, p, size=(n, n, cols), dtype=np.int64)
            return cls(p, pi, (D + q + q.transpose(1, 0, 2)) % p, None)
        pdeg = max(N - 1, 1)
        pb = monomial_basis(n, pdeg)
        A = [np.zeros((pb.sizes[pdeg], 1), dtype=np.int64) for _ in range(n)]
        for i in range(n):
            for j in range(n):
                A[i][pb.index[tuple(1 if v == j else 0 for v in range(n))]] = D[i, j]
        lowest = 3 if kind == "degenerate" else 2
        kb = monomial_basis(n, max(N, lowest))
        for idx in range(kb.sizes[lowest - 1], kb.sizes[kb.degree]):  # d/dp_i of k_m p^m
            m = [int(v) for v in kb.exponents[idx]]
            coef = int(rng.integers(0, p))
            for i in range(n):
                if m[i] and sum(m) - 1 <= pdeg:
                    lower = m.copy()
                    lower[i] -= 1
                    row = pb.index[tuple(lower)]
                    A[i][row] = (A[i][row] + coef * m[i]) % p
        linear_part = np.array([[A[i][pb.index[tuple(1 if v == j else 0 for v in range(n))]] for j in range(n)]
                                for i in range(n)])
        return cls(p, pi, linear_part, PolynomialShift(A, p, pdeg))

    def jets(self, trees, max_order: int, K: np.ndarray, basis: MonomialBasis) -> dict[Tree, np.ndarray]:
        """F(t) jets of the Hamiltonian K (coefficients over ``basis``, first variables x)."""
        if self.shift is None:
            return constant_matrix_jets(trees, max_order, K, self.D, self.p, basis, jets=True)
        return self.shift.jets(trees, max_order, K, basis, jets=True)


def _bernoulli_plus(n: int) -> list[Fraction]:
    """B_0..B_n with B_1 = +1/2: phi(z) = z / (1 - e^-z) = sum B_k^+ z^k / k!."""
    B = [Fraction(1)]
    for m in range(1, n + 1):
        B.append(-sum(comb(m + 1, k) * B[k] for k in range(m)) / (m + 1))
    if n >= 1:
        B[1] = Fraction(1, 2)
    return B


def _composite_partials(alpha_increment, H, dim: int, ring2: JetRing):
    """partials(J, m) = d_p^J f(x0 + xi, 0) for f = H(x0 + y(xi, p)), y = alpha - x0 as jets in (xi, p)."""
    basis2 = ring2.basis
    D = basis2.degree
    y = alpha_increment  # list of dim jets in 2*dim variables, zero constant term
    # powers y^a for every exponent a of H's basis, by multiplying one factor at a time
    hbasis = monomial_basis(dim, D)
    batch = H.shape[1]
    one = np.zeros((basis2.sizes[D], batch), dtype=ring2.dtype)
    one[0] = 1
    powers = {tuple([0] * dim): one}
    f = ring2.reduce(one * H[0][None, :])
    for idx in range(1, hbasis.sizes[D]):
        e = tuple(int(x) for x in hbasis.exponents[idx])
        v = next(i for i in range(dim) if e[i])
        lower = list(e)
        lower[v] -= 1
        powers[e] = ring2.mul(powers[tuple(lower)], y[v], D)
        f = ring2.reduce(f + ring2.reduce(powers[e] * H[idx][None, :]))
    index2 = basis2.index
    xi_basis = monomial_basis(dim, D)

    @cache
    def composite_rows(J, m):
        pexp, scale = _exponent(J, dim)
        ids = [index2[tuple(int(x) for x in xi_basis.exponents[i]) + pexp]
               for i in range(xi_basis.sizes[m])]
        return np.array(ids, dtype=np.int64), scale

    def partials(J, m):
        ids, scale = composite_rows(J, m)
        return ring2.reduce(f[ids] * scale)

    return partials


class ExactScalar:
    """One residue mod p per random instance (shape (batch,)): a coefficient of a family's
    structure in :func:`general_values`. Numbers (int, Fraction, float read exactly) combine."""

    __slots__ = ("p", "values")

    def __init__(self, p: int, values: np.ndarray):
        self.p = p
        self.values = values % p

    def _residue(self, other):
        return other.values if isinstance(other, ExactScalar) else to_residue(Fraction(other), self.p)

    def __mul__(self, other):
        if isinstance(other, ExactJet):
            return other * self
        return ExactScalar(self.p, self.values * self._residue(other))

    __rmul__ = __mul__

    def __ne__(self, other):
        return bool(np.any((self.values - self._residue(other)) % self.p))


class ExactJet:
    """A jet mod p truncated at the ring's degree, shape (M, batch): + - * with jets, exact
    scalars and numbers (the arithmetic of a family's base program, `rkhp.systems.families`)."""

    __slots__ = ("ring", "coef")

    def __init__(self, ring: JetRing, coef: np.ndarray):
        self.ring = ring
        self.coef = coef

    def _scalar(self, other):
        if isinstance(other, ExactScalar):
            return other.values[None, :]
        return to_residue(Fraction(other), self.ring.p)

    def __add__(self, other):
        if isinstance(other, ExactJet):
            return ExactJet(self.ring, self.ring.reduce(self.coef + other.coef))
        coef = self.coef.copy()
        coef[0] = self.ring.reduce(coef[0] + self._scalar(other))
        return ExactJet(self.ring, coef)

    __radd__ = __add__

    def __neg__(self):
        return ExactJet(self.ring, self.ring.reduce(-self.coef))

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if isinstance(other, ExactJet):
            return ExactJet(self.ring, self.ring.mul(self.coef, other.coef, self.ring.basis.degree))
        return ExactJet(self.ring, self.ring.reduce(self.coef * self._scalar(other)))

    __rmul__ = __mul__


def _exact_exp(w: ExactJet) -> ExactJet:
    """exp(w) for a jet w with zero constant term (its truncated series)."""
    if np.any(w.coef[0] % w.ring.p):
        raise ValueError("exact exp needs an argument with zero constant term")
    return ExactJet(w.ring, _exp(w.ring, w.coef, w.ring.basis.degree))


def _exact_phimv(K, x):
    """phi(K) x = sum_k B_k^+/k! K^k x for K with zero constant terms (entries may be 0), to the
    ring's degree: K^k x has degree >= k."""
    ring = x[0].ring
    D = ring.basis.degree
    n = len(x)
    coeffs = [to_residue(b / factorial(k), ring.p) for k, b in enumerate(_bernoulli_plus(D))]
    term, out = list(x), list(x)
    for k in range(1, D + 1):
        term = [sum((K[i][j] * term[j] for j in range(n) if isinstance(K[i][j], ExactJet)), 0 * x[0])
                for i in range(n)]
        out = [out[i] + term[i] * coeffs[k] for i in range(n)]
    return out


def _no_closed_form(p):
    raise ValueError("the so(3)* closed form is float-only; use the structure's phi(K) x")


#: the functions of a family's base program on exact jets (`rkhp.systems.families`)
EXACT_FUNCTIONS = SimpleNamespace(exp=_exact_exp, phimv=_exact_phimv, crb=_no_closed_form)


def _random_structure(family: str, dim: int, batch: int, rng: np.random.Generator, p: int):
    """A random instance of a family's structure mod p: so(3)* for lie-poisson (dim 3), random
    antisymmetric lambda or pi (one per instance) for log-canonical and constant."""
    if family == LIE_POISSON:
        if dim != 3:
            raise ValueError("the Lie–Poisson instances here are so(3)*, dimension 3")
        return LieAlgebra(SO3)
    if family not in (LOG_CANONICAL, CONSTANT):
        raise ValueError(f"no random instances of family {family!r}")
    upper = rng.integers(0, p, size=(dim, dim, batch), dtype=np.int64)
    matrix = np.empty((dim, dim), dtype=object)
    for i in range(dim):
        for j in range(dim):
            matrix[i, j] = ExactScalar(p, upper[i, j] - upper[j, i])
    return matrix


def general_values(trees, max_order: int, family: str, batch: int, rng: np.random.Generator,
                   p: int, dim: int = 3, realisation: str = "symmetric") -> dict[Tree, np.ndarray]:
    """F(t) at a random base point x0 for random Hamiltonian jets, modulo p.

    The birealisation is the registry's: the base alpha of `family` (`rkhp.systems.families`) on
    a random instance of its structure (so(3)* for ``"lie-poisson"``, random antisymmetric
    lambda or pi in dimension ``dim`` for ``"log-canonical"`` and ``"constant"``), composed with
    the shift of `realisation` (`rkhp.systems.core`; e.g. ``"quartic"``: degenerate but not
    symmetric, the control on which the symmetric relations must fail, docs/theory.md §8).
    """
    D = max(max_order - 1, 1)
    basis2 = monomial_basis(2 * dim, D)
    ring2 = JetRing(basis2, p)
    size2 = basis2.sizes[D]

    def variable(k):
        v = np.zeros((size2, batch), dtype=np.int64)
        e = [0] * (2 * dim)
        e[k] = 1
        v[basis2.index[tuple(e)]] = 1
        return ExactJet(ring2, v)

    x0 = rng.integers(1, p, size=(dim, batch), dtype=np.int64)
    structure = _random_structure(family, dim, batch, rng, p)
    x = [variable(i) + ExactScalar(p, x0[i]) for i in range(dim)]
    pv = [variable(dim + i) for i in range(dim)]
    shift = realisation_kind(realisation).shift(pv)
    shifted = x if shift is None else [xi + si for xi, si in zip(x, shift, strict=True)]
    alpha = poisson_family(family).base(structure, 1.0)(shifted, pv, EXACT_FUNCTIONS)
    y = [ring2.reduce(a.coef - _constant(x0[i], size2)) for i, a in enumerate(alpha)]
    hbasis = monomial_basis(dim, D)
    H = rng.integers(0, p, size=(hbasis.sizes[D], batch), dtype=np.int64)
    partials = _composite_partials(y, H, dim, ring2)
    ring = JetRing(monomial_basis(dim, D), p)
    return elementary_differentials(trees, max_order, ring, partials, lambda grad, m: grad)


def _constant(values: np.ndarray, size: int) -> np.ndarray:
    c = np.zeros((size, values.shape[0]), dtype=np.int64)
    c[0] = values
    return c


def _exp(ring: JetRing, w: np.ndarray, m: int) -> np.ndarray:
    """exp(w) truncated at degree m for a jet w with zero constant term."""
    total = np.zeros_like(w)
    total[0] = 1
    power = total.copy()
    for k in range(1, m + 1):
        power = ring.reduce(ring.mul(power, w, m) * to_residue(Fraction(1, k), ring.p))
        total = ring.reduce(total + power)
    return total
