"""Modified and modifying Hamiltonians of RKHP methods: backward error analysis (docs/theory.md §11).

An RKHP step of character a has the generating function S_h = sum_t h^|t| a(t)/sigma(t) F(t)
(paper Theorem 5.1; F(t) the elementary Hamiltonians, docs/theory.md §5). Its *modified
Hamiltonian* is H~ = sum_t h^(|t|-1) beta(t)/sigma(t) F(t) whose exact Hamilton–Jacobi flow (the
exponential exp^↷ of paper §3, eq. (17) ``eq:e``) has the generating function S_h: the step is the
exact time-h flow of H~. The *modifying Hamiltonian* H^ is the other way round: the RKHP step of H^
is the exact flow of H (BSeries.jl's ``modifying_integrator``).

The F(t) carry linear relations, and F of a combination of F(t) is not a tree-wise substitution
(the pitfall of docs/theory.md §11), so beta is found order by order on generic instances,
exactly (§11, "An exact and universal way"):

1. generic systems of the class, as Taylor jets at a base point with residues modulo a prime below
   2^31 (:mod:`rkhp.series.differentials`): random antisymmetric pi, random polynomial H, and for the
   general and degenerate classes a random shift of the realisation (§4, §8);
2. with the step h a graded variable of the jets, the series of K_(k-1) = H_0 + ... + h^(k-1) H_(k-1)
   is computed to h^(k+1); the residual against the target series at h^(k+1) is H_k at the base
   points (times the inner character's a(b));
3. H_k = sum_t c_t F(t) over the canonical basis of order k + 1: an overdetermined linear system
   over the instances. Inconsistent: no tree series exists at that order (:class:`NotATreeSeries`,
   confirmed modulo a second prime); consistent: c is the same for every instance;
4. radical weights (a tableau with sqrt(3)) live in a number field Q(theta): the computation runs
   once per root of theta's minimal polynomial modulo p (:class:`rkhp.base.modular.FieldEmbeddings`),
   and the coordinates come back over several primes by CRT and rational reconstruction,
   confirmed modulo a further prime.

Canonical form (the coefficients are unique only modulo the relations of the class):
``general``: every tree of T; ``degenerate``: every tree of T_0 (the generic instances carry no
relation among them: checked on every run); ``symmetric``: the T_0 trees that are not the leading
tree of a relation of ``rkhp relations`` (docs/theory.md §8), coefficients on the leading trees
being folded into the others with those relations.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from functools import lru_cache

import numpy as np

from ..base.bounds import seed as check_seed
from ..base.errors import CheckFailed, InputError, NumericalFailure
from ..base.modular import FieldEmbeddings, Inconsistent, rref_fraction, rref_mod, solve_over_primes, to_residue
from ..trees.conditions import check_class
from ..trees.relations import shipped_order
from ..trees.rooted import LEAF, Tree, check_order, format_tree, trees_of_order, trees_up_to
from .differentials import RandomRealisations, monomial_basis

#: Largest order of a modified or modifying Hamiltonian (the symmetric relations ship to order 8).
MAX_ORDER = 8
#: Dimension of the generic instances: the F(t) of the basis are independent there up to order 8.
DIMENSION = 4
#: Instances beyond the number of basis trees of the largest order.
EXTRA_INSTANCES = 4
#: Largest degree of the weights' number field (the solve runs once per embedding).
MAX_FIELD_DEGREE = 8
#: Primes tried before giving up on rational reconstruction.
MAX_PRIMES = 8
KINDS = ("modified", "modifying")


class NotATreeSeries(CheckFailed):
    """The term of order ``order`` is not a combination of the F(t) of the class (exact check)."""

    def __init__(self, message: str, order: int):
        super().__init__(message)
        self.order = order


@dataclass(frozen=True)
class HamiltonianSeries:
    """A series sum_t h^(|t|-1) c(t) F(t), c(t) = beta(t)/sigma(t) in the canonical basis.

    Attributes:
        kind: ``"modified"`` (the step is the exact flow of this series) or ``"modifying"``
            (the step applied to this series is the exact flow of H).
        cls: ``general`` (T), ``degenerate`` (T_0) or ``symmetric`` (T_0 modulo relations).
        order: largest tree order N (the series stops at h^(N-1)).
        basis: per order 1..N, the canonical basis trees.
        coefficients: the nonzero c(t), exact (Fraction, or a sympy number in the weights' field).
        checks: how it was computed (primes, instances, dimension, seed).
    """

    kind: str
    cls: str
    order: int
    basis: tuple[tuple[Tree, ...], ...]
    coefficients: dict
    checks: dict = field(default_factory=dict, compare=False)

    def coefficient(self, t: Tree):
        """c(t) = beta(t)/sigma(t) (0 for a tree outside the basis or with no term)."""
        return self.coefficients.get(t, Fraction(0))

    def terms(self) -> list[tuple[Tree, object]]:
        """The nonzero terms (tree, c(t)) by increasing order, canonical tree order within."""
        return [(t, self.coefficients[t]) for level in self.basis for t in level if t in self.coefficients]

    def float_terms(self) -> list[tuple[Tree, float]]:
        """The terms with float64 coefficients (for evaluation on a system)."""
        return [(t, _to_float(c)) for t, c in self.terms()]

    def truncated(self, order: int) -> HamiltonianSeries:
        """The same series up to ``order``."""
        check_order(order, self.order, what="truncation order")
        coefficients = {t: c for t, c in self.coefficients.items() if t.order <= order}
        return HamiltonianSeries(self.kind, self.cls, order, self.basis[:order], coefficients, self.checks)


# ----------------------------------------------------------------------------- public API


def modified_hamiltonian(character: Mapping, order: int, cls: str = "general", seed: int = 0) -> HamiltonianSeries:
    """H~ with exp^↷(H~) = the method's generating function (module docstring).

    ``character``: a(t) for every tree of the class up to ``order`` (a tableau's exact weights, see
    :func:`method_character`, or any character; Fractions, integers or sympy algebraic numbers).
    Raises NotATreeSeries when a term of H~ is not a combination of the F(t) of the class.
    """
    return _hamiltonian_series("modified", character, order, cls, seed)


def modifying_hamiltonian(character: Mapping, order: int, cls: str = "general", seed: int = 0) -> HamiltonianSeries:
    """H^ whose RKHP step (character a) is the exact flow of H: S_a[H^] = S_e[H]."""
    return _hamiltonian_series("modifying", character, order, cls, seed)


def method_character(method, order: int) -> dict[Tree, object]:
    """The character a(t) on T up to ``order`` of a method: a tableau (its exact elementary weights,
    docs/theory.md §2), or a :class:`rkhp.integrators.methods.Method` of kind rkhp (its tableau's) or taylor
    (the THP of order N, paper Thm 5.1: e(t) for |t| <= N, over T_0 for ``thpN-t0``, 0 elsewhere)."""
    from ..tableaux.tableau import Tableau
    from ..tableaux.weights import elementary_weights

    if isinstance(method, Tableau):
        tableau = method
    elif method.kind == "taylor":
        return {t: t.e if t.order <= method.order and (t.in_t0 or not method.degenerate) else Fraction(0)
                for t in trees_up_to(order)}
    else:
        tableau = method.rkhp_tableau("the modified Hamiltonian")
    if not tableau.is_exact:
        raise InputError(f"{tableau.name}: the modified Hamiltonian is exact and needs exact tableau entries "
                         f"(rationals or radicals), but some are given as decimals")
    return elementary_weights(tableau, order, "exact")


def canonical_basis(n: int, cls: str) -> tuple[Tree, ...]:
    """The canonical basis trees of order n (module docstring)."""
    check_class(cls)
    trees = trees_of_order(n, degenerate=cls != "general")
    if cls != "symmetric" or not trees:
        return trees
    leading = set(_symmetric_reduction(n)[1])
    return tuple(t for t in trees if t not in leading)


def canonical_coefficients(coefficients: Mapping, n: int, cls: str) -> dict[Tree, object]:
    """A combination sum_t c_t F(t) of order n written in the canonical basis (exact).

    Symmetric class: the relations of ``rkhp relations`` fold the coefficient of each leading tree
    into the others; the other classes keep every tree. Zero coefficients are dropped.
    """
    check_class(cls)
    trees = trees_of_order(n, degenerate=cls != "general")
    c = {t: coefficients.get(t, 0) for t in trees}
    if cls == "symmetric" and trees:
        rows, leading = _symmetric_reduction(n)
        for row, lead in zip(rows, leading):
            factor = c[lead]
            if factor != 0:
                for t, r in zip(trees, row):
                    if r:
                        c[t] = c[t] - factor * r
    return {t: v for t, v in c.items() if not _is_exact_zero(v)}


# ----------------------------------------------------------------------------- the solve


@dataclass
class _Problem:
    kind: str
    cls: str
    order: int
    inner: dict  # character of the unknown's series
    target: dict  # character of H's series
    embeddings: object
    basis: tuple[tuple[Tree, ...], ...]
    seed: int


def _hamiltonian_series(kind: str, character: Mapping, order: int, cls: str, seed: int) -> HamiltonianSeries:
    check_seed(seed)
    check_class(cls)
    check_order(order, MAX_ORDER, what="order of the modified Hamiltonian")
    trees = trees_up_to(order, degenerate=cls != "general")
    method = read_character(character, trees)
    exact = {t: t.e for t in trees}
    inner, target = (exact, method) if kind == "modified" else (method, exact)
    if _is_exact_zero(inner[LEAF]):
        raise InputError("a(b) = 0: the method is not consistent, its steps are no near-identity flows")
    embeddings = FieldEmbeddings(field_of(method.values()))
    if embeddings.degree > MAX_FIELD_DEGREE:
        raise InputError(f"the weights lie in a number field of degree {embeddings.degree}: the exact solve runs "
                         f"once per embedding and handles degree <= {MAX_FIELD_DEGREE}")
    basis = tuple(canonical_basis(n, cls) for n in range(1, order + 1))
    problem = _Problem(kind, cls, order, inner, target, embeddings, basis, seed)
    coordinates, checks = _series_coordinates(problem)
    coefficients = {}
    for level in basis:
        for t in level:
            value = embeddings.element(coordinates[t])
            if not _is_exact_zero(value):
                coefficients[t] = value
    return HamiltonianSeries(kind, cls, order, basis, coefficients, checks)


def _series_coordinates(problem: _Problem):
    """Coordinates of every basis coefficient, over primes until a further prime confirms."""
    keys = [t for level in problem.basis for t in level]
    try:
        coordinates, primes, last = solve_over_primes(
            lambda p, roots, rng: _solve_modulo(problem, p, roots, rng), keys, problem.embeddings, problem.seed,
            MAX_PRIMES)
    except Inconsistent as exc:
        n = exc.order
        raise NotATreeSeries(
            f"order {n}: the h^{n - 1} term of the {problem.kind} Hamiltonian is not a combination "
            f"of the elementary Hamiltonians F(t), |t| = {n}, of the {problem.cls} class (an exact "
            f"check modulo two primes); its tree series stops at order {n - 1}", n) from None
    except ValueError:
        raise NumericalFailure(f"the {problem.kind} Hamiltonian's coefficients did not reconstruct with "
                               f"{MAX_PRIMES} primes (rerun with another --seed)") from None
    checks = {"primes": primes, "confirmed_modulo": last, "instances": _batch(problem),
              "dimension": DIMENSION, "seed": problem.seed,
              "field_degree": problem.embeddings.degree, "family": _FAMILY_TEXT[problem.cls]}
    return coordinates, checks


def _batch(problem: _Problem) -> int:
    return len(problem.basis[-1]) + EXTRA_INSTANCES


def _solve_modulo(problem: _Problem, p: int, roots, rng):
    """Residues of the coordinates of every basis coefficient modulo p, or the first order whose
    term is outside the span of the F(t) (an int)."""
    d = len(roots)
    batch = _batch(problem)
    ncols = d * batch
    N = problem.order
    n = DIMENSION
    trees_class = trees_up_to(N, degenerate=problem.cls != "general")
    family = _family(problem.cls, n, N, ncols, rng, p)
    bx = monomial_basis(n, max(N - 1, 0))
    H = rng.integers(0, p, size=(bx.sizes[-1], ncols), dtype=np.int64)
    FH = family(trees_class, N, H, bx)
    emb = problem.embeddings
    images = {id(problem.inner): {}, id(problem.target): {}}

    def residues(character, t) -> np.ndarray:
        memo = images[id(character)]
        if t not in memo:
            memo[t] = np.repeat(np.array(emb.images(character[t], p, roots), dtype=np.int64), batch)
        return memo[t]

    inner_b_inv = np.array([pow(int(x), -1, p) for x in residues(problem.inner, LEAF)], dtype=np.int64)
    # order 1: inner(b) H_0 = target(b) H
    c0 = residues(problem.target, LEAF) * inner_b_inv % p
    H_terms = {0: H * c0[None, :] % p}
    out = {LEAF: tuple(int(x) for x in emb.coordinates_mod(c0[::batch], p, roots))}
    for k in range(1, N):
        level = problem.basis[k]
        r = (_target_part(FH, problem.target, k + 1, problem.cls, residues, p)
             - _inner_part(family, problem.inner, H_terms, k, n, problem.cls, residues, bx, p)) % p
        r = r * inner_b_inv % p
        if not level:
            if r.any():
                return k + 1
            H_terms[k] = np.zeros((bx.sizes[N - 1 - k], ncols), dtype=np.int64)
            continue
        solution = np.zeros((len(level), ncols), dtype=np.int64)
        for e in range(d):
            cols = slice(e * batch, (e + 1) * batch)
            V = np.array([FH[t][0][cols] for t in level], dtype=np.int64).T
            rows, pivots = rref_mod(np.concatenate([V, r[cols, None]], axis=1), p)
            if len(level) in pivots:
                return k + 1
            if pivots != tuple(range(len(level))):
                raise NumericalFailure(f"order {k + 1}: the generic instances give dependent F(t) on the "
                                       f"canonical basis (modulo {p}); rerun with another --seed")
            solution[:, cols] = rows[: len(level), -1][:, None]
        for j, t in enumerate(level):
            out[t] = tuple(int(x) for x in emb.coordinates_mod(solution[j, ::batch], p, roots))
        size = bx.sizes[N - 1 - k]
        Hk = np.zeros((size, ncols), dtype=np.int64)
        for j, t in enumerate(level):
            Hk = (Hk + FH[t][:size] * solution[j][None, :]) % p
        H_terms[k] = Hk
    _check_independent(FH, problem, batch, p)
    return out


def _target_part(FH, target, n, cls, residues, p) -> np.ndarray:
    """[sum_t h^|t| target(t)/sigma(t) F_H(t)]_(h^n) at the base points."""
    total = 0
    for t in trees_of_order(n, degenerate=cls != "general"):
        total = (total + residues(target, t) * to_residue(Fraction(1, t.sigma), p) % p * FH[t][0]) % p
    return total


def _inner_part(family, inner, H_terms, k, n, cls, residues, bx, p) -> np.ndarray:
    """[sum_u h^|u| inner(u)/sigma(u) F_K(u)]_(h^(k+1)) at the base points, K = sum_(j<k) h^j H_j.

    K is a jet in (x, h), h of weight 1 in the total degree (docs/theory.md §11): F_K(u) is then
    computed exactly to total degree k + 1 - |u| by the same recursion as F_H.
    """
    bxh = monomial_basis(n + 1, k)
    ncols = H_terms[0].shape[1]
    K = np.zeros((bxh.sizes[k], ncols), dtype=np.int64)
    for j, Hj in H_terms.items():
        rows = _graded_rows(n, k, j)
        K[rows] = (K[rows] + Hj[: len(rows)]) % p
    trees = trees_up_to(k + 1, degenerate=cls != "general")
    FK = family(trees, k + 1, K, bxh)
    total = 0
    for u in trees:
        row = bxh.index[(0,) * n + (k + 1 - u.order,)]
        total = (total + residues(inner, u) * to_residue(Fraction(1, u.sigma), p) % p * FK[u][row]) % p
    return total


@lru_cache(maxsize=64)
def _graded_rows(n: int, k: int, j: int) -> np.ndarray:
    """Rows of the (x, h) basis of degree k holding x^e h^j, for the x-monomials e of degree <= k - j."""
    bx = monomial_basis(n, k)
    bxh = monomial_basis(n + 1, k)
    return np.array([bxh.index[tuple(int(v) for v in bx.exponents[i]) + (j,)] for i in range(bx.sizes[k - j])],
                    dtype=np.int64)


def _check_independent(FH, problem: _Problem, batch: int, p: int) -> None:
    """The generic instances carry no relation among the basis trees (the canonical form is a basis)."""
    for level in problem.basis:
        if len(level) > 1:
            V = np.array([FH[t][0][:batch] for t in level], dtype=np.int64).T
            if len(rref_mod(V, p)[1]) < len(level):
                raise NumericalFailure(f"order {level[0].order}: the F(t) of the canonical basis are dependent on "
                                       f"the generic instances (modulo {p}); rerun with another --seed")


# ----------------------------------------------------------------------------- generic instances


_FAMILY_TEXT = {
    "symmetric": "constant pi, alpha = x - pi p / 2 (symmetric)",
    "degenerate": "constant pi shifted by the flow of a random K(p) of degrees 3..N, alpha = x - pi p / 2 + grad K(p)"
                  " (degenerate, not symmetric), one realisation for all instances",
    "general": "constant pi shifted by the flow of a random K(p) of degrees 2..N, alpha = x - pi p / 2 + grad K(p)"
               " (not degenerate), one realisation for all instances",
}


def _family(cls: str, n: int, N: int, ncols: int, rng, p: int):
    """jets(trees, max_order, K, basis): F(t) jets of K on random instances of the class
    (:class:`rkhp.series.differentials.RandomRealisations`)."""
    return RandomRealisations.of_class(cls, n, N, ncols, rng, p).jets


# ----------------------------------------------------------------------------- helpers


@lru_cache(maxsize=16)
def _symmetric_reduction(n: int):
    """The shipped relations of order n in reduced echelon form: (rows, leading tree of each)."""
    o = shipped_order(n)
    if not o.relations:
        return (), ()
    rows, pivots = rref_fraction(o.relations)
    return rows, tuple(o.trees[k] for k in pivots)


def read_character(character: Mapping, trees) -> dict:
    from ..tableaux.tableau import parse_entry

    out = {}
    for t in trees:
        if t not in character:
            raise InputError(f"the character has no value on the tree {format_tree(t)}")
        x = character[t]
        if isinstance(x, int) and not isinstance(x, bool):
            x = Fraction(x)
        if not isinstance(x, Fraction):
            x = parse_entry(x, where=f"a({format_tree(t)})")
            if not isinstance(x, Fraction) and not hasattr(x, "is_algebraic"):
                raise InputError(f"a({format_tree(t)}) must be exact (a rational or an algebraic number), "
                                 f"got {character[t]!r}")
        out[t] = x
    return out


def field_of(values):
    """The number field of the values (None for Q): :func:`rkhp.tableaux.weights.number_field`."""
    from ..tableaux.weights import number_field

    return number_field(values)


def _is_exact_zero(x) -> bool:
    if isinstance(x, (int, Fraction)):
        return x == 0
    return bool(x.is_zero)


def _to_float(x) -> float:
    if isinstance(x, (int, Fraction)):
        return float(x)
    return float(x.evalf(30))


def coefficient_text(x) -> str:
    """The exact coefficient as text: ``-1/6``, ``-1/480 + sqrt(3)/1920``."""
    return str(x)
