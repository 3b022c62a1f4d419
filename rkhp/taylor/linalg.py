"""Dense linear algebra in compiled code, without allocation: the LU factorisation with partial
pivoting of the spray kernel's Newton matrices (`rkhp.taylor.composites`), of the engine's Newton
solve (`rkhp.integrators.engine.solve_small`), of the direct Euler steps' chord matrices and of the
stage Newton solve's Jacobian (hundreds of unknowns: `rkhp.integrators.engine._stage_newton`)."""

from __future__ import annotations

from .compiler import NJIT_NORC
from .compiler import numba as nb

#: columns of a panel of `lu_factor`
LU_PANEL = 32


@nb.njit(**NJIT_NORC)
def lu_factor(A, perm):
    """LU factorisation with partial pivoting in place (perm: the row order); False if singular.

    Right-looking and blocked by panels of `LU_PANEL` columns (Golub & Van Loan, Matrix
    Computations, §3.2.10): a panel is factorised column by column, then its rows of U are solved
    for, then the trailing rows are updated by the panel's columns, eight entries of a row at a
    time held in registers while the panel's columns are applied in order. Every entry receives
    the same operations in the same order as in the column-by-column algorithm, so the pivots and
    the factors are the same to the last bit (tests/test_linalg.py); the column-by-column
    update reads and writes the whole trailing matrix once per column, out of cache for the
    matrices of the stage Newton solve (hundreds of unknowns, `rkhp.integrators.engine`)."""
    n = A.shape[0]
    for i in range(n):
        perm[i] = i
    for k0 in range(0, n, LU_PANEL):
        k1 = min(k0 + LU_PANEL, n)
        for c in range(k0, k1):
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
                for j in range(c + 1, k1):
                    A[i, j] -= f * A[c, j]
        if k1 == n:  # the last panel: nothing to its right (a matrix of one panel: the classical loop)
            break
        for p in range(k0 + 1, k1):
            for q in range(k0, p):
                f = A[p, q]
                for j in range(k1, n):
                    A[p, j] -= f * A[q, j]
        _trailing_update(A, k0, k1)
    return True


@nb.njit(inline="always", **NJIT_NORC)
def _trailing_update(A, k0, k1):
    """A[i, j] -= sum_p A[i, p] A[p, j] for i, j >= k1, p from k0 to k1 - 1 in order (one
    subtraction per p, as in the column-by-column algorithm): eight consecutive entries of row i
    in registers over all p, the rest of the row one p at a time."""
    n = A.shape[0]
    j8 = k1 + (n - k1) // 8 * 8
    for i in range(k1, n):
        for j in range(k1, j8, 8):
            a0, a1, a2, a3 = A[i, j], A[i, j + 1], A[i, j + 2], A[i, j + 3]
            a4, a5, a6, a7 = A[i, j + 4], A[i, j + 5], A[i, j + 6], A[i, j + 7]
            for p in range(k0, k1):
                f = A[i, p]
                a0 -= f * A[p, j]
                a1 -= f * A[p, j + 1]
                a2 -= f * A[p, j + 2]
                a3 -= f * A[p, j + 3]
                a4 -= f * A[p, j + 4]
                a5 -= f * A[p, j + 5]
                a6 -= f * A[p, j + 6]
                a7 -= f * A[p, j + 7]
            A[i, j], A[i, j + 1], A[i, j + 2], A[i, j + 3] = a0, a1, a2, a3
            A[i, j + 4], A[i, j + 5], A[i, j + 6], A[i, j + 7] = a4, a5, a6, a7
        for p in range(k0, k1):
            f = A[i, p]
            for j in range(j8, n):
                A[i, j] -= f * A[p, j]


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
