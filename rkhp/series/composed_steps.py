"""The series of a composition of RKHP steps, against the Butcher product (docs/theory.md §11).

Paper Proposition 4.2 (``prop:composition``) and Theorem 4.3 (``thm:somewhat``) state that the
Butcher product a1 * a2 (:func:`rkhp.trees.algebra.compose`, a1 applied first) describes the product of
the jets of bisections. Two compositions can be meant:

- the *groupoid product* of the bisections, i.e. the RKHP steps composed as maps, y -> y' -> y''
  (paper eq. (9) ``eq:comp_bislag``): what an integrator does;
- the *Hamilton–Jacobi composition*: the series as maps on 1-forms, zeta -> zeta + B^(h xi)(a)(zeta)
  (paper eq. (21) ``eq:comp_Bseries``), the second evaluated at the first's result, i.e. the
  Hamilton–Jacobi series restarted from the first bisection instead of the zero section.

:func:`composition_series` computes both generating functions exactly, on generic instances of the
class modulo primes (as :mod:`rkhp.series.modified`), as combinations of the F(t) in the canonical basis,
next to the Butcher product. Steps all have the size h. On the generic instances, in a dimension
where pi is invertible (4):

- groupoid product: apply the steps to the identity jet y = w (Taylor jets in (w, h), h graded),
  solving alpha(x, grad S_k(x)) = y by fixed-point iteration (one power of h per sweep); then
  (x, p) from alpha(x, p) = y_0, beta(x, p) = y_N (beta - alpha = pi p), x inverted as a function,
  and grad S(x) = p: its h^m coefficient at the base point against sum_t c(t)/sigma grad F(t);
- Hamilton–Jacobi composition: S_(k+1) = S_k + sum_t h^|t| a_(k+1)(t)/sigma(t) F(t)[S_k], where
  F(t)[S] are the elementary Hamiltonians at the base section dS (paper §3: d_p^m f(x, grad S(x))
  in place of d_p^m f(x, 0)), over every tree of T: off the zero section the trees outside T_0 do
  not vanish. Computed for realisations linear in p.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from ..base.bounds import seed as check_seed
from ..base.errors import InputError, NumericalFailure
from ..base.modular import FieldEmbeddings, Inconsistent, rref_mod, solve_over_primes, to_residue
from ..trees.algebra import compose
from ..trees.conditions import check_class
from ..trees.rooted import Tree, check_order, trees_of_order, trees_up_to
from .differentials import JetRing, RandomRealisations, elementary_differentials, monomial_basis
from .modified import MAX_FIELD_DEGREE, canonical_basis, canonical_coefficients, field_of, read_character

#: Largest order of a composition series.
MAX_ORDER = 7
#: Dimension of the generic instances (even: pi invertible).
DIMENSION = 4
EXTRA_INSTANCES = 4
MAX_PRIMES = 8


@dataclass(frozen=True)
class CompositionSeries:
    """Generating functions of a composition of steps of size h, exact, per canonical basis tree.

    Attributes:
        names: the steps' names, in the order they are applied.
        cls: the class (general, degenerate, symmetric).
        order: largest tree order.
        basis: per order, the canonical basis trees (rkhp.series.modified.canonical_basis).
        groupoid: c(t) of the steps composed as maps (groupoid product), to ``groupoid_order``.
        groupoid_order: the largest order to which the groupoid product is a tree series.
        restart: c(t) of the Hamilton–Jacobi composition (None when not computed: realisations
            of the class that are not linear in p).
        butcher: c(t) of the Butcher product a_1 * ... * a_k (a_1 applied first, the convention of
            rkhp.trees.algebra.compose), in the canonical form.
        butcher_reversed: c(t) of a_k * ... * a_1: the product that paper Proposition 4.2 assigns
            to the composed map, since L_1 . L_2 induces phi_1 o phi_2 (paper eq. (9)).
        checks: primes, instances, dimension, seed.
    """

    names: tuple[str, ...]
    cls: str
    order: int
    basis: tuple[tuple[Tree, ...], ...]
    groupoid: dict
    groupoid_order: int
    restart: dict | None
    butcher: dict
    butcher_reversed: dict
    checks: dict = field(default_factory=dict, compare=False)

    def first_difference(self, which: str, against: str = "butcher") -> int | None:
        """The first order at which ``which`` ("groupoid" or "restart") differs from ``against``
        ("butcher" or "butcher_reversed"); None when they agree as far as both are computed."""
        series = self.groupoid if which == "groupoid" else self.restart
        top = self.groupoid_order if which == "groupoid" else self.order
        other = getattr(self, against)
        for level in self.basis[:top]:
            if any(not _equal(series.get(t, 0), other.get(t, 0)) for t in level):
                return level[0].order
        return None


def composition_series(characters, order: int, cls: str = "symmetric", names=None, seed: int = 0) -> CompositionSeries:
    """The composition of steps with the given characters (each a mapping tree -> exact a(t) on T),
    applied in the order given (module docstring)."""
    check_seed(seed)
    check_class(cls)
    check_order(order, MAX_ORDER, what="order of the composition")
    if len(characters) < 2:
        raise InputError("a composition needs at least two steps")
    all_trees = trees_up_to(order)
    chars = [read_character(a, all_trees) for a in characters]
    field_ = field_of([v for a in chars for v in a.values()])
    embeddings = FieldEmbeddings(field_)
    if embeddings.degree > MAX_FIELD_DEGREE:
        raise InputError(f"the weights lie in a number field of degree {embeddings.degree} (at most "
                         f"{MAX_FIELD_DEGREE} here)")
    if field_ is not None:
        import sympy

        chars = [{t: sympy.Rational(v.numerator, v.denominator) if isinstance(v, Fraction) else v
                  for t, v in a.items()} for a in chars]
    basis = tuple(canonical_basis(n, cls) for n in range(1, order + 1))
    butcher = _butcher(chars, order, cls)
    butcher_reversed = _butcher(chars[::-1], order, cls)
    names = tuple(names) if names else tuple(f"method {k + 1}" for k in range(len(chars)))
    groupoid, groupoid_order, checks = _groupoid(chars, order, cls, basis, embeddings, seed)
    restart = _restart(chars, order, cls, basis, embeddings, seed) if cls != "degenerate" else None
    checks["family"] = ("constant pi, alpha = x + A(p), A = D p (symmetric: D = -pi/2; general: D = Q - pi/2)"
                        if cls != "degenerate" else "constant pi, alpha = x - pi p / 2 + grad K(p), K of degrees 3..N")
    return CompositionSeries(names, cls, order, basis, groupoid, groupoid_order, restart, butcher, butcher_reversed,
                             checks)


def _butcher(chars, order: int, cls: str) -> dict:
    """c(t) = (a_1 * ... * a_k)(t)/sigma(t) in the canonical form of the class."""
    product = chars[0]
    for a in chars[1:]:
        product = compose(product, a, order)
    out = {}
    for n in range(1, order + 1):
        level = {t: product[t] / t.sigma for t in trees_of_order(n, cls != "general")}
        out.update(canonical_coefficients(level, n, cls))
    return {t: _simplify(v) for t, v in out.items() if not _equal(v, 0)}


# ----------------------------------------------------------------------------- exact solves


def _groupoid(chars, order, cls, basis, embeddings, seed):
    top = order
    while top >= 1:
        try:
            coords, checks = _composition_coordinates(
                lambda p, roots, rng, n=top: _groupoid_modulo(chars, n, cls, basis[:n], embeddings, p, roots, rng),
                basis[:top], embeddings, seed)
            return _elements(coords, embeddings), top, checks
        except Inconsistent as exc:
            top = exc.order - 1
    return {}, 0, {}


def _restart(chars, order, cls, basis, embeddings, seed):
    coords, _ = _composition_coordinates(
        lambda p, roots, rng: _restart_modulo(chars, order, cls, basis, embeddings, p, roots, rng),
        basis, embeddings, seed)
    return _elements(coords, embeddings)


def _composition_coordinates(compute, basis, embeddings, seed):
    keys = [t for level in basis for t in level]
    try:
        coords, primes, last = solve_over_primes(compute, keys, embeddings, seed, MAX_PRIMES)
    except ValueError:
        raise NumericalFailure(f"the composition's coefficients did not reconstruct with {MAX_PRIMES} primes "
                               f"(rerun with another --seed)") from None
    return coords, {"primes": primes, "confirmed_modulo": last, "dimension": DIMENSION, "seed": seed}


def _elements(coords, embeddings) -> dict:
    out = {}
    for t, c in coords.items():
        value = embeddings.element(c)
        if value != 0:
            out[t] = value
    return out


# ----------------------------------------------------------------------------- modulo p


class _Jets:
    """Truncated polynomials in (w_1..w_n, h), total degree N, modulo p, one column per instance."""

    def __init__(self, n: int, N: int, ncols: int, p: int):
        self.n, self.N, self.ncols, self.p = n, N, ncols, p
        self.basis = monomial_basis(n + 1, N)
        self.ring = JetRing(self.basis, p)
        self.size = self.basis.sizes[N]
        self.xbasis = monomial_basis(n, N)
        ex = self.basis.exponents
        self._x_index = np.array([self.xbasis.index[tuple(int(v) for v in e[:n])] for e in ex], dtype=np.intp)
        self._h_power = ex[:, n].astype(np.intp)
        self._shift = {}

    def zero(self) -> np.ndarray:
        return np.zeros((self.size, self.ncols), dtype=np.int64)

    def variable(self, k: int) -> np.ndarray:
        v = self.zero()
        v[1 + k] = 1  # graded order: degree-1 monomials follow the constant, variable k at 1 + k
        return v

    def monomial(self, e_x: tuple[int, ...], j: int) -> int:
        return self.basis.index[e_x + (j,)]

    def shift_h(self, jet: np.ndarray, j: int) -> np.ndarray:
        """jet times h^j."""
        if j == 0:
            return jet
        if j not in self._shift:
            src, dst = [], []
            for i, e in enumerate(self.basis.exponents):
                if e.sum() + j <= self.N:
                    up = tuple(int(v) for v in e[:-1]) + (int(e[-1]) + j,)
                    src.append(i)
                    dst.append(self.basis.index[up])
            self._shift[j] = (np.array(src, dtype=np.intp), np.array(dst, dtype=np.intp))
        src, dst = self._shift[j]
        out = self.zero()
        out[dst] = jet[src]
        return out

    def powers(self, X: list[np.ndarray], degree: int) -> np.ndarray:
        """X^e for the x-monomials e of degree <= ``degree`` (X: n jets without constant term)."""
        xb = self.xbasis
        out = np.zeros((xb.sizes[degree], self.size, self.ncols), dtype=np.int64)
        out[0, 0] = 1
        for idx in range(1, xb.sizes[degree]):
            e = [int(v) for v in xb.exponents[idx]]
            v = next(i for i in range(self.n) if e[i])
            e[v] -= 1
            out[idx] = self.ring.mul(out[xb.index[tuple(e)]], X[v], self.N)
        return out

    def substitute(self, G: np.ndarray, powers: np.ndarray) -> np.ndarray:
        """G(x, h) with x replaced by the jets whose powers are given."""
        p = self.p
        out = self.zero()
        for j in range(self.N + 1):
            rows = np.nonzero((self._h_power == j) & (self._x_index < len(powers)))[0]
            rows = rows[G[rows].any(axis=1)]
            if not len(rows):
                continue
            terms = powers[self._x_index[rows]] * G[rows][:, None, :] % p
            out = (out + self.shift_h(terms.sum(axis=0) % p, j)) % p
        return out

    def matvec(self, M: np.ndarray, X: list[np.ndarray]) -> list[np.ndarray]:
        """M X for matrices (n, n, columns or 1)."""
        return [sum(M[i, j][None, :] * X[j] % self.p for j in range(self.n)) % self.p for i in range(self.n)]


def _apply_A(jets: _Jets, real, X: list[np.ndarray]) -> list[np.ndarray]:
    """A(X) for the realisation alpha = x + A(p) (X without constant term)."""
    if real.shift is None:
        return jets.matvec(real.D, X)
    shift = real.shift
    pb = shift.pbasis
    powers = jets.powers(X, pb.degree)
    out = []
    for i in range(jets.n):
        total = jets.zero()
        for idx in range(1, pb.sizes[pb.degree]):
            c = int(shift.A[i][idx, 0])
            if c:
                total = (total + powers[jets.xbasis.index[tuple(int(v) for v in pb.exponents[idx])]] * c) % jets.p
        out.append(total)
    return out


def _instances(order, cls, basis, p, roots, rng, linear: bool):
    """Generic instances: (n, embeddings count, batch, columns, realisation, x-basis, H, F_H jets).

    F_H over the class's trees to degree order + 1 - |t|, H to degree ``order``: gradients of the
    generating functions are then exact to total degree ``order`` in (x, h)."""
    n = DIMENSION
    d = len(roots)
    batch = -(-len(basis[-1]) // n) + EXTRA_INSTANCES
    ncols = d * batch
    real = RandomRealisations.of_class(cls, n, order + 1, ncols, rng, p, linear=linear)
    bx = monomial_basis(n, order)
    H = rng.integers(0, p, size=(bx.sizes[-1], ncols), dtype=np.int64)
    FH = real.jets(trees_up_to(order, degenerate=cls != "general"), order + 1, H, bx)
    return n, d, batch, ncols, real, bx, H, FH


def _weights(emb, a, t, p, roots, batch) -> np.ndarray:
    """a(t)/sigma(t) per column: the images of a(t) under each root, repeated over its batch."""
    images = np.repeat(np.array(emb.images(a[t], p, roots), dtype=np.int64), batch)
    return images * to_residue(Fraction(1, t.sigma), p) % p


def _graded(J, bx, jet, j: int) -> np.ndarray:
    """An x-jet (over bx) times h^j as a jet of J, keeping total degrees <= J.N."""
    out = J.zero()
    for k in range(len(jet)):
        e = tuple(int(v) for v in bx.exponents[k])
        if sum(e) + j <= J.N:
            out[J.monomial(e, j)] = jet[k]
    return out


def _solve_levels(levels, V_of, rhs, d, batch, p):
    """Per basis level, the coefficients solving V c = rhs per embedding block; an int (the order)
    when inconsistent."""
    out = {}
    for level in levels:
        if not level:
            continue
        for t in level:
            out[t] = []
        for e in range(d):
            V, r = V_of(level, e), rhs(level[0].order, e)
            rows, pivots = rref_mod(np.concatenate([V, r[:, None]], axis=1), p)
            if len(level) in pivots:
                return level[0].order
            if pivots != tuple(range(len(level))):
                raise NumericalFailure(f"order {level[0].order}: dependent F(t) on the generic instances modulo "
                                       f"{p}; rerun with another --seed")
            for j, t in enumerate(level):
                out[t].append(int(rows[j, -1]))
    return out


def _groupoid_modulo(chars, order, cls, basis, emb, p, roots, rng):
    n, d, batch, ncols, real, bx, H, FH = _instances(order, cls, basis, p, roots, rng, linear=cls != "degenerate")
    J = _Jets(n, order, ncols, p)
    xring = JetRing(bx, p)
    grads = []
    for a in chars:  # grad S_k = sum_t h^|t| a(t)/sigma(t) grad F(t), exact to total degree N
        g = [J.zero() for _ in range(n)]
        for t in FH:
            if t.order <= order:
                w = _weights(emb, a, t, p, roots, batch)
                if w.any():
                    for i in range(n):
                        g[i] = (g[i] + w * _graded(J, bx, xring.derivative(FH[t], i, order - t.order), t.order)) % p
        grads.append(g)
    w0 = [J.variable(k) for k in range(n)]
    y = w0
    for g in grads:
        y = _step(J, real, g, y)
    P = J.matvec(_inverse_matrices(real.pi, p), [(y[i] - w0[i]) % p for i in range(n)])
    # x = w - A(P(w)) = z: w = z + A(P(w))
    w = _fixed_point(J, lambda w: [(w0[i] + a) % p for i, a in enumerate(_apply_A(J, real, _at(J, P, w)))], w0)
    grad = _at(J, P, w)

    def groupoid_columns(level, e):
        cols = slice(e * batch, (e + 1) * batch)
        return np.array([np.concatenate([FH[t][1 + i][cols] for i in range(n)]) for t in level], dtype=np.int64).T

    def groupoid_rhs(m, e):
        cols = slice(e * batch, (e + 1) * batch)
        return np.concatenate([grad[i][J.monomial((0,) * n, m)][cols] for i in range(n)])

    out = _solve_levels(basis, groupoid_columns, groupoid_rhs, d, batch, p)
    if isinstance(out, int):
        return out
    return {t: emb.coordinates_mod(v, p, roots) for t, v in out.items()}


def _step(J, real, g: list[np.ndarray], y: list[np.ndarray]) -> list[np.ndarray]:
    """One RKHP step of generating-function gradient g: alpha(x, g(x)) = y by fixed point, then
    y' = beta(x, g(x)) = y + pi g(x)."""
    p = J.p
    x = _fixed_point(J, lambda x: [(yi - a) % p for yi, a in zip(y, _apply_A(J, real, _at(J, g, x)))], y)
    return [(yi + v) % p for yi, v in zip(y, J.matvec(real.pi, _at(J, g, x)))]


def _at(J, G: list[np.ndarray], x: list[np.ndarray]) -> list[np.ndarray]:
    """The jets G_i(x, h) with x replaced by the jets x (powers computed once)."""
    powers = J.powers(x, J.N)
    return [J.substitute(gi, powers) for gi in G]


def _fixed_point(J, update, start: list[np.ndarray]) -> list[np.ndarray]:
    """Iterate x <- update(x) from ``start`` until x stops changing: each sweep fixes one more
    power of h (the update is a contraction by O(h)), so at most N + 1 sweeps."""
    x = start
    for _ in range(J.N + 1):
        nxt = update(x)
        if all(np.array_equal(a, b) for a, b in zip(nxt, x)):
            return nxt
        x = nxt
    return x


def _restart_modulo(chars, order, cls, basis, emb, p, roots, rng):
    n, d, batch, ncols, real, bx, H, FH = _instances(order, cls, basis, p, roots, rng, linear=True)
    J = _Jets(n, order, ncols, p)
    all_trees = trees_up_to(order)
    derivs = {(): _graded(J, bx, H, 0)}

    def dH(index):
        if index not in derivs:
            derivs[index] = _padded(J, J.ring.derivative(dH(index[:-1]), index[-1], order - len(index)))
        return derivs[index]

    def restart_transform(grad, m):
        return J.matvec(real.D, grad)

    S = J.zero()  # S_1 = B(a_1)(0): at the zero section only the class's trees count
    for t in FH:
        if t.order <= order:
            S = (S + _weights(emb, chars[0], t, p, roots, batch) * _graded(J, bx, FH[t], t.order)) % p
    for a in chars[1:]:  # S_(k+1) = S_k + B(a)(S_k), every tree of T at the base section dS_k
        g = [_padded(J, J.ring.derivative(S, i, order - 1)) for i in range(n)]
        Dg = J.matvec(real.D, g)
        powers = J.powers([(J.variable(i) + Dg[i]) % p for i in range(n)], order)
        cache: dict = {}

        def restart_partials(index, m, powers=powers, cache=cache):
            if index not in cache:
                cache[index] = J.substitute(dH(index), powers)
            return cache[index][: J.ring.size(m)]

        F = elementary_differentials(all_trees, order, J.ring, restart_partials, restart_transform, n, jets=True)
        for t in all_trees:
            S = (S + _weights(emb, a, t, p, roots, batch) * J.shift_h(_padded(J, F[t]), t.order)) % p

    def restart_columns(level, e):
        cols = slice(e * batch, (e + 1) * batch)
        return np.array([FH[t][0][cols] for t in level], dtype=np.int64).T

    def restart_rhs(m, e):
        return S[J.monomial((0,) * n, m)][e * batch:(e + 1) * batch]

    out = _solve_levels(basis, restart_columns, restart_rhs, d, batch, p)
    if isinstance(out, int):
        raise NumericalFailure(f"order {out}: the Hamilton–Jacobi composition is not a tree series on the generic "
                               f"instances modulo {p}; rerun with another --seed")
    return {t: emb.coordinates_mod(v, p, roots) for t, v in out.items()}


def _padded(J, jet) -> np.ndarray:
    out = J.zero()
    out[: len(jet)] = jet
    return out


def _inverse_matrices(M: np.ndarray, p: int) -> np.ndarray:
    """The inverse modulo p of each matrix M[:, :, k]."""
    n = M.shape[0]
    out = np.zeros_like(M)
    for k in range(M.shape[2]):
        rows, pivots = rref_mod(np.concatenate([M[:, :, k], np.eye(n, dtype=np.int64)], axis=1), p)
        if pivots[:n] != tuple(range(n)):
            raise NumericalFailure(f"a random Poisson matrix is singular modulo {p}; rerun with another --seed")
        out[:, :, k] = rows[:n, n:]
    return out


def _equal(x, y) -> bool:
    d = x - y
    return d == 0 if isinstance(d, (int, Fraction)) else bool(_simplify(d) == 0)


def _simplify(x):
    if isinstance(x, (int, Fraction)):
        return Fraction(x)
    import sympy

    x = sympy.radsimp(sympy.expand(x))
    return Fraction(int(x.p), int(x.q)) if x.is_Rational else x
