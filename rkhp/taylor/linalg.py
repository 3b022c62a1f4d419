"""Small dense linear algebra in compiled code, without allocation: the LU factorisation with
partial pivoting of the spray kernel's Newton matrices (`rkhp.taylor.composites`) and of the
engine's Newton solve (`rkhp.integrators.engine.newton_solve`), and the max-norm of the
integrators' stopping tests (`max_abs`)."""

from __future__ import annotations

from .compiler import NJIT_NORC
from .compiler import numba as nb


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
def max_abs(v):
    """The largest |v_k| (NaN if any component is NaN)."""
    r = 0.0
    for q in range(v.shape[0]):
        a = abs(v[q])
        if not a <= r:  # also catches NaN
            r = a
    return r
