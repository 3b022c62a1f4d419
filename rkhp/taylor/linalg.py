"""Small dense linear algebra in compiled code, without allocation: the LU factorisation with
partial pivoting of the spray kernel's Newton matrices (`rkhp.taylor.composites`) and of the
engine's Newton solve (`rkhp.integrators.engine.newton_solve`), the explicit inverse of the direct
forms' chord matrices (`inverse_transposed`) and its product with a vector (`transposed_product`),
and the max-norm of the integrators' stopping
tests (`max_abs`); in Python, the allocation of work arrays on cache lines for them
(`aligned_zeros`, `padded`)."""

from __future__ import annotations

import numpy as np

from .compiler import NJIT_NORC
from .compiler import numba as nb

LINE = 64
"""Bytes of a cache line, the alignment of `aligned_zeros`."""


def padded(m: int) -> int:
    """m rounded up to whole cache lines of float64 (rows of this length keep every row of an
    `aligned_zeros` matrix on a line boundary)."""
    per_line = LINE // 8
    return -(-m // per_line) * per_line


def aligned_zeros(shape) -> np.ndarray:
    """float64 zeros of `shape` whose first element starts a cache line: a vectorised loop over a
    row (`inverse_transposed`, the spray direct form's product with a chord matrix's inverse) then
    loads whole vectors, where a row that straddles lines costs up to twice the time (the offset of
    numpy's own allocation varies from one process to the next)."""
    size = int(np.prod(shape))
    buffer = np.zeros(size + LINE // 8)
    skip = (-buffer.ctypes.data % LINE) // 8
    return buffer[skip: skip + size].reshape(shape)


@nb.njit(**NJIT_NORC)
def lu_factor(A, perm):
    """LU factorisation with partial pivoting in place (perm: the row order); False if singular."""
    n = A.shape[0]
    for i in range(n):
        perm[i] = i
    for c in range(n):
        piv = c
        for i in range(c + 1, n):
            if abs(A[i, c]) > abs(A[piv, c]):
                piv = i
        if not abs(A[piv, c]) > 0.0:
            return False
        if piv != c:
            for j in range(n):
                A[c, j], A[piv, j] = A[piv, j], A[c, j]
            perm[c], perm[piv] = perm[piv], perm[c]
        for i in range(c + 1, n):
            f = A[i, c] / A[c, c]
            A[i, c] = f
            for j in range(c + 1, n):
                A[i, j] -= f * A[c, j]
    return True


@nb.njit(**NJIT_NORC)
def lu_solve(LU, perm, b, tmp):
    """b := A^-1 b from the factors of `lu_factor` (tmp: a work vector as long as b)."""
    n = LU.shape[0]
    for i in range(n):
        acc = b[perm[i]]
        for j in range(i):
            acc -= LU[i, j] * tmp[j]
        tmp[i] = acc
    for i in range(n - 1, -1, -1):
        acc = tmp[i]
        for j in range(i + 1, n):
            acc -= LU[i, j] * tmp[j]
        tmp[i] = acc / LU[i, i]
    for i in range(n):
        b[i] = tmp[i]


@nb.njit(**NJIT_NORC)
def inverse_transposed(A, perm, X):
    """A := (A^-1)^T in place (A, X: m x m; X and perm are work space), from `lu_factor`'s factors
    by forward and back substitution on the m columns of the identity at once: each update is a
    row of X times a scalar, a contiguous loop the compiler vectorises. Stored transposed, the
    inverse's product with a vector runs over contiguous columns (A[c] is column c of A^-1).
    False (A left factorised) if A is singular."""
    m = A.shape[0]
    if not lu_factor(A, perm):
        return False
    for r in range(m):
        for c in range(m):
            X[r, c] = 1.0 if c == perm[r] else 0.0
    for c in range(m):
        for r in range(c + 1, m):
            f = A[r, c]
            for k in range(m):
                X[r, k] -= f * X[c, k]
    for c in range(m - 1, -1, -1):
        d = A[c, c]
        for k in range(m):
            X[c, k] /= d
        for r in range(c):
            f = A[r, c]
            for k in range(m):
                X[r, k] -= f * X[c, k]
    for r in range(m):
        for c in range(m):
            A[c, r] = X[r, c]
    return True


@nb.njit(inline="always", **NJIT_NORC)
def transposed_product(Bt, v, out, m):
    """out[:m] := B v[:m] for a matrix B stored transposed (Bt[c, :m] is column c of B, as
    `inverse_transposed` leaves an inverse): the sum of the columns times v's entries, each a
    contiguous loop of fixed length m, which the compiler vectorises (B's rows would be strided
    reads; the triangular solves of LU factors are chains of dependent updates, with a division a
    row). out and v are distinct arrays. Inlined into the iterations that call it."""
    for r in range(m):
        out[r] = 0.0
    for c in range(m):
        x = v[c]
        for r in range(m):
            out[r] += Bt[c, r] * x


@nb.njit(**NJIT_NORC)
def max_abs(v):
    """The largest |v_k| (NaN if any component is NaN)."""
    r = 0.0
    for q in range(v.shape[0]):
        a = abs(v[q])
        if not a <= r:  # also catches NaN
            r = a
    return r
