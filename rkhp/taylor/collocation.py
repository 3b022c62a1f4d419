"""Gauss–Legendre collocation on [0, 1] with the weights of an average (docs/theory.md §9).

For Q nodes c (the Gauss–Legendre nodes of [0, 1]) and the Lagrange basis l_j on them:

- ``A[i, j] = int_0^{c_i} l_j`` (the Gauss collocation matrix), ``b[j] = int_0^1 l_j`` (the
  Gauss weights);
- ``w[j] = int_0^1 (1 - s) l_j(s) ds = b_j (1 - c_j)`` (both are the interpolatory rule of the
  weight 1 - s on Q nodes; Gauss quadrature integrates (1 - s) l_j exactly), the weights of
  int_0^1 u(s) ds = u(0) + int_0^1 (1 - s) u'(s) ds for the collocation polynomial u.

Symmetry of the nodes (c_(Q+1-i) = 1 - c_i) gives A_(Q+1-i, Q+1-j) = b_j - A_ij and
w_(Q+1-j) = b_j - w_j, which makes the spray realisation computed with them exactly symmetric
(beta(x, p) = alpha(x, -p)). Computed in float64 from numpy's Gauss–Legendre rule: the integrals
of the degree-(Q-1) basis are Gauss quadratures on [0, c_i] (exact), so the tables are correct to
a few units of round-off.
"""

from __future__ import annotations

import math
from functools import cache
from typing import NamedTuple

import numpy as np

from .ops import SPRAY_MAX_NODES as MAX_NODES


class Collocation(NamedTuple):
    """The tables for Q nodes (see the module): nodes c, A (Q x Q), b, w."""

    nodes: np.ndarray
    A: np.ndarray
    b: np.ndarray
    w: np.ndarray


def _lagrange(nodes: np.ndarray, s: np.ndarray) -> np.ndarray:
    """out[j] = l_j(s) for every j (the products in the order of the nodes, element by element)."""
    q = len(nodes)
    out = np.ones((q, *s.shape))
    for k, c in enumerate(nodes):
        others = np.arange(q) != k
        out[others] = out[others] * (s - c) / (nodes[others] - c).reshape(-1, *[1] * s.ndim)
    return out


def _integrals(nodes: np.ndarray, t: np.ndarray, g: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """M[i, j] = int_0^{ends_i} l_j by the Gauss rule (t, g) of [-1, 1] mapped to [0, ends_i]."""
    basis = _lagrange(nodes, ends[:, None] * (t + 1.0) / 2.0)
    return np.array([[0.5 * c * np.dot(g, basis[j, i]) for j in range(len(nodes))]
                     for i, c in enumerate(ends)])


@cache
def collocation(q: int) -> Collocation:
    """The Gauss–Legendre collocation tables on [0, 1] with q nodes."""
    t, g = np.polynomial.legendre.leggauss(q)
    nodes, b = (t + 1.0) / 2.0, g / 2.0
    return Collocation(nodes, _integrals(nodes, t, g, nodes), b, b * (1.0 - nodes))


def average_error_constant(q: int) -> float:
    """E_Q = (Q!)^2 / ((2Q)!^2 (2Q + 1)): for y' = lambda y, the average computed with Q nodes
    gives alpha with the relative error (-1)^Q E_Q lambda^(2Q) + O(lambda^(2Q+1)) (measured
    against mpmath for Q = 1..6; docs/theory.md §9.3)."""
    return math.factorial(q) ** 2 / (math.factorial(2 * q) ** 2 * (2 * q + 1))


def prolongation(q: int) -> np.ndarray:
    """P[i, j] = int_0^{c'_i} l_j for the nodes c' of q + 1 points and the basis l_j of q:
    the q-node collocation polynomial u (u' = sum_j X_j l_j) at the q + 1 nodes is
    u(c'_i) = u(0) + sum_j P_ij X_j (a start for the solve with one node more)."""
    t, g = np.polynomial.legendre.leggauss(q)
    return _integrals(collocation(q).nodes, t, g, collocation(q + 1).nodes)


def _tables():
    """Every table up to MAX_NODES, stacked for the compiled kernel: A[q, :q, :q], B[q, :q],
    W[q, :q], E[q] and P[q, :q + 1, :q] (`prolongation`; index q = number of nodes; row 0
    unused)."""
    A = np.zeros((MAX_NODES + 1, MAX_NODES, MAX_NODES))
    B = np.zeros((MAX_NODES + 1, MAX_NODES))
    W = np.zeros((MAX_NODES + 1, MAX_NODES))
    E = np.full(MAX_NODES + 1, np.inf)
    P = np.zeros((MAX_NODES + 1, MAX_NODES, MAX_NODES))
    for q in range(1, MAX_NODES + 1):
        t = collocation(q)
        A[q, :q, :q], B[q, :q], W[q, :q], E[q] = t.A, t.b, t.w, average_error_constant(q)
        if q < MAX_NODES:
            P[q, :q + 1, :q] = prolongation(q)
    return A, B, W, E, P


TABLE_A, TABLE_B, TABLE_W, TABLE_E, TABLE_P = _tables()
