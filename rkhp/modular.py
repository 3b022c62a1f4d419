"""Exact linear algebra modulo primes, Chinese remaindering and rational reconstruction.

Used by :mod:`rkhp.relations` (NOTES §8) to find the linear relations among elementary
differentials exactly: the evaluations are integers modulo word-sized primes (numpy int64, every
product of two residues below 2^62), the row-reduced echelon forms modulo two primes are combined
by the Chinese remainder theorem into residues modulo a ~2^62 modulus, the rationals are recovered
by rational reconstruction (Wang's half-gcd bound) and the result is confirmed modulo a third
prime. Nothing here uses floating point.
"""

from __future__ import annotations

from fractions import Fraction
from math import isqrt

import numpy as np

#: Primes just below 2^31: a product of two residues fits in a signed 64-bit integer.
PRIMES = (2147483647, 2147483629, 2147483587, 2147483579, 2147483563, 2147483549)


def rref_mod(matrix, p: int) -> tuple[np.ndarray, tuple[int, ...]]:
    """Reduced row echelon form of an integer matrix modulo the prime p.

    Returns (rows, pivots): the nonzero rows of the RREF (int64, entries in [0, p)) and the pivot
    column of each. The rank is ``len(pivots)``.
    """
    a = np.array(matrix, dtype=np.int64) % p
    if a.ndim != 2:
        raise ValueError("rref_mod expects a matrix")
    rows, cols = a.shape
    pivots: list[int] = []
    r = 0
    for c in range(cols):
        if r == rows:
            break
        nz = np.nonzero(a[r:, c])[0]
        if nz.size == 0:
            continue
        k = r + int(nz[0])
        if k != r:
            a[[r, k]] = a[[k, r]]
        a[r] = a[r] * pow(int(a[r, c]), -1, p) % p
        factors = a[:, c].copy()
        factors[r] = 0
        nonzero = np.nonzero(factors)[0]
        if nonzero.size:
            a[nonzero] = (a[nonzero] - (factors[nonzero, None] * a[r][None, :]) % p) % p
        pivots.append(c)
        r += 1
    return a[:r], tuple(pivots)


def nullspace_mod(matrix, p: int) -> np.ndarray:
    """A basis of the right null space {v : M v = 0} modulo p, in reduced row echelon form."""
    a = np.array(matrix, dtype=np.int64)
    cols = a.shape[1]
    rows, pivots = rref_mod(a, p)
    free = [c for c in range(cols) if c not in pivots]
    basis = np.zeros((len(free), cols), dtype=np.int64)
    for k, f in enumerate(free):
        basis[k, f] = 1
        for i, c in enumerate(pivots):
            basis[k, c] = (-int(rows[i, f])) % p
    if not free:
        return basis
    return rref_mod(basis, p)[0]


def crt_pair(r1: int, p1: int, r2: int, p2: int) -> int:
    """The residue modulo p1*p2 that is r1 mod p1 and r2 mod p2 (p1, p2 coprime)."""
    return (r1 + p1 * ((r2 - r1) * pow(p1, -1, p2) % p2)) % (p1 * p2)


def rational_reconstruction(a: int, m: int) -> Fraction:
    """The fraction n/d with |n|, d <= sqrt(m/2) and n = a d (mod m) (Wang's algorithm).

    Raises ValueError when no such fraction exists: the modulus is too small for the answer, or
    the residue does not come from a small rational.
    """
    bound = isqrt(m // 2)
    r0, r1 = m, a % m
    s0, s1 = 0, 1
    while r1 > bound:
        q = r0 // r1
        r0, r1 = r1, r0 - q * r1
        s0, s1 = s1, s0 - q * s1
    if s1 == 0 or abs(s1) > bound:
        raise ValueError(f"no rational with numerator and denominator below {bound} is {a} mod {m}")
    value = Fraction(r1, s1)
    if (value.numerator - a * value.denominator) % m:
        raise ValueError(f"rational reconstruction of {a} mod {m} is inconsistent")
    return value


def to_residue(x: Fraction | int, p: int) -> int:
    """The residue of a rational number modulo p (its denominator must be prime to p)."""
    x = Fraction(x)
    return x.numerator * pow(x.denominator, -1, p) % p


def rref_fraction(rows) -> tuple[tuple[tuple[Fraction, ...], ...], tuple[int, ...]]:
    """Exact reduced row echelon form over the rationals: (nonzero rows, pivot columns)."""
    a = [[Fraction(x) for x in row] for row in rows]
    if not a:
        return (), ()
    cols = len(a[0])
    pivots: list[int] = []
    r = 0
    for c in range(cols):
        k = next((i for i in range(r, len(a)) if a[i][c] != 0), None)
        if k is None:
            continue
        a[r], a[k] = a[k], a[r]
        inv = 1 / a[r][c]
        a[r] = [x * inv for x in a[r]]
        for i in range(len(a)):
            if i != r and a[i][c] != 0:
                f = a[i][c]
                a[i] = [x - f * y for x, y in zip(a[i], a[r])]
        pivots.append(c)
        r += 1
        if r == len(a):
            break
    return tuple(tuple(row) for row in a[:r]), tuple(pivots)
