"""The elementary differentials F(t) of a system as Taylor jets, compiled (paper eq. (22), Thm 5.1,
docs/theory.md §5, §11): what the THP step (`rkhp.integrators.taylor`) and a modified Hamiltonian
(`rkhp.integrators.modified_energy`) evaluate.

F(b) = H, F(b[t1..tm])(x) = d^m_p f(x, 0)[grad F(t1)(x), ..., grad F(tm)(x)], f = H o alpha. At a
point x0 each F(t) is a jet in dx = x - x0 truncated at degree margin + N - |t| (N: the largest
order; enough for every use as a subtree; margin 2 gives the root's gradient and its Jacobian,
margin 0 values only). The multilinear derivative of a node is read off f(x0 + dx, sum_r eps_r
grad F(u_r)) in the variables (dx, eps), one eps_r per distinct child u_r: the coefficient of
prod eps_r^k_r times prod k_r!. The tape interpreter runs f at its address (`rkhp.taylor.interpreter.run_from`)
in the jet space of n + q variables for a node of q distinct children (q <= 3 for |t| <= 9: one
space per q, each of the largest degree its trees take; a jet truncated below a space's degree
uses a prefix of its tables).

`tree_jets` builds the compiled data (`TreeJets`: a `TreeTable` of index arrays, computed once in
Python per system and set of trees); `addresses` takes the addresses of its tapes, spaces and work
arrays on the stack of the compiled function it is inlined into; `elementary` fills F(t) at a point
for every tree; `tree_values` is a compiled loop of sum_t w_t F(t)(x) over states.
"""

from __future__ import annotations

from functools import lru_cache
from itertools import groupby
from math import factorial
from typing import NamedTuple

import numpy as np

from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.interpreter import address_of, as_plain, interpreter, run_from, tape_work
from ..taylor.jets import jet_space, monomials
from .engine_state import SystemTapes

SPACES = 4
"""Jet spaces of a tree evaluation: n + q variables for q = 0 (the leaf, the gradients, alpha and
beta) to 3 distinct children (the most a tree of order 9 or less has: orders 1 + 2 + 3 + 3 > 8)."""


class TreeTable(NamedTuple):
    """The trees t_0, t_1, ... (closed under taking subtrees, by increasing order) as arrays.

    Per tree: power (float64) |t|; degree, the jet degree D of F(t); space, its number q of
    distinct children (the jet space's index; 0 for the leaf); run_degree, the degree it is
    evaluated at (D for the leaf, D + m for m children); symmetry, prod k_r! over its distinct
    children's multiplicities; e and sigma (float64), paper's e(t) and sigma(t); child_start,
    (trees + 1,) offsets of its distinct children in `child`. Per distinct child c: child[c], the
    tree's index; slot_start[c], slot_count[c]: the rows of `slots` that hold dx^a eps_r for the
    monomials a of its gradient's jet (the gradient's coefficient m goes to row
    slots[slot_start[c] + m]). coefficient_start (trees + 1,): the rows of `coefficients` holding
    dx^a prod eps_r^k_r of each tree, the coefficient of F(t) at dx^a. hessian (n, n): the index
    of dx_k dx_l in a jet of n variables."""

    power: np.ndarray
    degree: np.ndarray
    space: np.ndarray
    run_degree: np.ndarray
    symmetry: np.ndarray
    e: np.ndarray
    sigma: np.ndarray
    child_start: np.ndarray
    child: np.ndarray
    slot_start: np.ndarray
    slot_count: np.ndarray
    slots: np.ndarray
    coefficient_start: np.ndarray
    coefficients: np.ndarray
    hessian: np.ndarray


class TreeJets(NamedTuple):
    """What `elementary` evaluates: the table, the system's plain tapes (f, H, alpha, beta), the
    address of their class's interpreter, the SPACES jet spaces (n + q variables), the
    interpreter's work arrays (as wide as the largest space) and F (trees, jet size): F(t)'s
    coefficients in the space of n variables."""

    table: TreeTable
    tapes: SystemTapes
    run: int
    spaces: tuple
    work: object
    F: np.ndarray


class TreeAddresses(NamedTuple):
    """The addresses of copies of the tapes, the spaces and the work arrays of a `TreeJets`, taken
    once in a compiled function (`addresses`) for its calls of the interpreter (`run_from`)."""

    f: object
    h: object
    alpha: object
    beta: object
    spaces: tuple
    work: object


@lru_cache(maxsize=256)
def _index(n_vars: int, degree: int) -> dict[tuple[int, ...], int]:
    return {m: i for i, m in enumerate(monomials(n_vars, degree))}


def _slot_rows(n: int, q: int, degree: int, r: int) -> list[int]:
    """Rows of the (dx, eps) jet space of degree `degree` holding dx^a eps_r, for the monomials a
    of degree <= degree - 1 in their order."""
    big = _index(n + q, degree)
    eps = tuple(1 if j == r else 0 for j in range(q))
    return [big[a + eps] for a in monomials(n, degree - 1)]


def _coefficient_rows(n: int, ks: tuple[int, ...], degree: int) -> list[int]:
    """Rows of the (dx, eps) jet space holding dx^a prod eps_r^k_r, for the monomials a of degree
    <= `degree`."""
    big = _index(n + len(ks), degree + sum(ks))
    return [big[a + ks] for a in monomials(n, degree)]


def tree_table(n: int, trees, order: int, margin: int) -> tuple[TreeTable, list[int]]:
    """The `TreeTable` of `trees` (closed under subtrees, by increasing order; |t| <= order) for
    a system of dimension n and jets of degree margin + order - |t|, and the degree each of the
    SPACES jet spaces needs (-1: unused)."""
    position = {t: i for i, t in enumerate(trees)}
    degrees = [max(margin + order - 1, 1)] + [-1] * (SPACES - 1)
    rows = {k: [] for k in ("power", "degree", "space", "run_degree", "symmetry", "e", "sigma")}
    child_start, child, slot_start, slot_count, slots = [0], [], [], [], []
    coefficient_start, coefficients = [0], []
    for t in trees:
        D = margin + order - t.order
        groups = [(u, len(list(g))) for u, g in groupby(t.children)]
        q, m = len(groups), len(t.children)
        if q >= SPACES:
            raise ValueError(f"a tree of {q} distinct children needs more than {SPACES} jet spaces")
        run_degree = D + m if q else D
        degrees[q] = max(degrees[q], run_degree)
        for r, (u, _) in enumerate(groups):
            rows_r = _slot_rows(n, q, run_degree, r)
            count = min(len(rows_r), int(jet_space(n, max(margin + order - u.order - 1, 0)).size))
            child.append(position[u])
            slot_start.append(len(slots))
            slot_count.append(count)
            slots += rows_r[:count]
        child_start.append(len(child))
        if q:
            coefficients += _coefficient_rows(n, tuple(c for _, c in groups), D)
        coefficient_start.append(len(coefficients))
        for key, value in (("power", t.order), ("degree", D), ("space", q), ("run_degree", run_degree),
                           ("symmetry", float(np.prod([factorial(c) for _, c in groups]))),
                           ("e", float(t.e)), ("sigma", t.sigma)):
            rows[key].append(value)
    index = _index(n, 2)
    hessian = np.array([[index[tuple((j == k) + (j == l) for j in range(n))] for l in range(n)] for k in range(n)],
                       dtype=np.int64).reshape(n, n)

    def ints(values):
        return np.array(values, dtype=np.int64)

    def floats(values):
        return np.array(values, dtype=np.float64)

    table = TreeTable(floats(rows["power"]), ints(rows["degree"]), ints(rows["space"]), ints(rows["run_degree"]),
                      floats(rows["symmetry"]), floats(rows["e"]), floats(rows["sigma"]), ints(child_start),
                      ints(child), ints(slot_start), ints(slot_count), ints(slots), ints(coefficient_start),
                      ints(coefficients), hessian)
    return table, degrees


def tree_jets(system, trees, order: int, margin: int) -> TreeJets:
    """The compiled data of the F(t) of `system` for `trees` (closed under subtrees, by increasing
    order, |t| <= `order`), jets of degree margin + order - |t| (`tree_table`)."""
    n = system.dim
    table, degrees = tree_table(n, tuple(trees), order, margin)
    spaces = tuple(jet_space(n + q, d) if d >= 0 else jet_space(0, 0) for q, d in enumerate(degrees))
    plain = SystemTapes(*(as_plain(t) for t in (system.f_tape, system.h_tape, system.alpha_tape, system.beta_tape)))
    work = tape_work(plain, max(s.size for s in spaces))
    F = np.zeros((len(table.degree), spaces[0].size))
    return TreeJets(table, plain, interpreter(system.f_tape).address, spaces, work, F)


@nb.njit(inline="always", **NJIT_NORC)
def addresses(jets):
    """`TreeAddresses` of `jets`: copies on the stack of the function this is inlined into
    (`rkhp.taylor.interpreter.address_of`), which live as long as its call."""
    t, s = jets.tapes, jets.spaces
    return TreeAddresses(address_of(t.f), address_of(t.h), address_of(t.alpha), address_of(t.beta),
                         (address_of(s[0]), address_of(s[1]), address_of(s[2]), address_of(s[3])),
                         address_of(jets.work))


@nb.njit(inline="always", **NJIT_NORC)
def elementary(jets, at, x0):
    """F(t) as a jet in dx at x0 for every tree, into jets.F (see the module)."""
    table, W, F = jets.table, jets.work.W, jets.F
    n = x0.shape[0]
    up, expo = jets.spaces[0].up, jets.spaces[0].expo
    for t in range(table.degree.shape[0]):
        q = table.space[t]
        D = table.run_degree[t]
        M = jets.spaces[q].counts[D]
        for k in range(n):
            for m in range(M):
                W[k, m] = 0.0
                W[n + k, m] = 0.0
            W[k, 0] = x0[k]
            if D >= 1:
                W[k, 1 + k] = 1.0
        if q == 0:
            run_from(jets.run, at.h, D, at.spaces[0], at.work)
            out = jets.tapes.h.outputs[0]
            for m in range(M):
                F[t, m] = W[out, m]
            continue
        for c in range(table.child_start[t], table.child_start[t + 1]):
            u, lo = table.child[c], table.slot_start[c]
            for k in range(n):
                for m in range(table.slot_count[c]):
                    W[n + k, table.slots[lo + m]] = (expo[m, k] + 1) * F[u, up[m, k]]
        run_from(jets.run, at.f, D, at.spaces[q], at.work)
        out = jets.tapes.f.outputs[0]
        w = table.symmetry[t]
        lo = table.coefficient_start[t]
        for m in range(table.coefficient_start[t + 1] - lo):
            F[t, m] = w * W[out, table.coefficients[lo + m]]


@nb.njit(**NJIT_NORC)
def tree_values(jets, terms, weights, states, out):
    """out[r] = sum_j weights[j] F(t_terms[j])(states[r]) for every state (values: any margin)."""
    at = addresses(jets)
    for r in range(states.shape[0]):
        elementary(jets, at, states[r])
        acc = 0.0
        for j in range(terms.shape[0]):
            acc += weights[j] * jets.F[terms[j], 0]
        out[r] = acc
