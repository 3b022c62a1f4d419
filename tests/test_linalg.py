"""The compiled LU factorisation (`rkhp.taylor.linalg`): the pivots and factors of the textbook
algorithm to the last bit, solutions against numpy's, and a singular matrix refused."""

from __future__ import annotations

import numpy as np
import pytest

from rkhp.taylor.linalg import aligned_zeros, inverse_transposed, lu_factor, lu_solve, padded


def column_by_column(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Gaussian elimination with partial pivoting, one column at a time (Golub & Van Loan,
    Algorithm 3.4.1), in numpy: (LU, row order, nonsingular)."""
    A = A.copy()
    n = A.shape[0]
    perm = np.arange(n)
    for c in range(n):
        piv = c + int(np.argmax(np.abs(A[c:, c])))
        if not abs(A[piv, c]) > 0.0:
            return A, perm, False
        A[[c, piv]] = A[[piv, c]]
        perm[[c, piv]] = perm[[piv, c]]
        A[c + 1:, c] /= A[c, c]
        A[c + 1:, c + 1:] -= np.outer(A[c + 1:, c], A[c, c + 1:])
    return A, perm, True


SIZES = (1, 2, 3, 7, 40, 150)


@pytest.mark.parametrize("n", SIZES)
def test_lu_equals_the_textbook_elimination_to_the_last_bit(n):
    rng = np.random.default_rng(n)
    A = rng.standard_normal((n, n)) * rng.uniform(0.1, 10.0, (n, 1))  # rows of mixed scales: pivoting
    LU, perm = A.copy(), np.zeros(n, np.int64)
    assert lu_factor(LU, perm)
    want, want_perm, ok = column_by_column(A)
    assert ok
    assert np.array_equal(perm, want_perm)
    assert np.array_equal(LU, want)  # bitwise, not approximately


@pytest.mark.parametrize("n", (5, 77))
def test_lu_solves_against_numpy(n):
    rng = np.random.default_rng(100 + n)
    A, b = rng.standard_normal((n, n)), rng.standard_normal(n)
    LU, perm = A.copy(), np.zeros(n, np.int64)
    assert lu_factor(LU, perm)
    x = b.copy()
    lu_solve(LU, perm, x, np.zeros(n))
    assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)


def test_a_zero_column_is_singular():
    A = np.random.default_rng(0).standard_normal((40, 40))
    A[:, 23] = 0.0
    assert not lu_factor(A, np.zeros(A.shape[0], np.int64))


@pytest.mark.parametrize("n", SIZES)
def test_the_transposed_inverse_against_numpy(n):
    rng = np.random.default_rng(100 + n)
    A = rng.standard_normal((n, n)) * rng.uniform(0.1, 10.0, (n, 1)) + 3.0 * np.eye(n)
    out, X = A.copy(), np.zeros((n, n))
    assert inverse_transposed(out, np.zeros(n, np.int64), X)
    want = np.linalg.inv(A)
    assert np.allclose(out.T, want, rtol=1e-10, atol=1e-12 * np.abs(want).max())
    assert np.allclose(A @ out.T, np.eye(n), atol=1e-11 * np.linalg.cond(A))


def test_the_inverse_of_a_singular_matrix_is_refused():
    A = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert not inverse_transposed(A, np.zeros(3, np.int64), np.zeros((3, 3)))


@pytest.mark.parametrize("shape", [(1,), (7,), (3, 5), (2, 9, 16)])
def test_aligned_zeros_start_on_a_cache_line(shape):
    a = aligned_zeros(shape)
    assert a.shape == shape and a.dtype == np.float64 and a.flags.c_contiguous
    assert a.ctypes.data % 64 == 0 and not a.any()


def test_padded_rows_are_whole_cache_lines():
    assert [padded(m) for m in (1, 8, 9, 16, 17, 208)] == [8, 8, 16, 16, 24, 208]
