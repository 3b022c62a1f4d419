"""Exact linear algebra modulo primes, Chinese remaindering and rational reconstruction.

Used by :mod:`rkhp.trees.relations` (docs/theory.md §8) to find the linear relations among elementary
differentials exactly: the evaluations are integers modulo word-sized primes (numpy int64, every
product of two residues below 2^62), the row-reduced echelon forms modulo two primes are combined
by the Chinese remainder theorem into residues modulo a ~2^62 modulus, the rationals are recovered
by rational reconstruction (Wang's half-gcd bound) and the result is confirmed modulo a third
prime. Nothing here uses floating point.
"""

from __future__ import annotations

from fractions import Fraction
from math import gcd, isqrt

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


# ----------------------------------------------------------------------------- number fields


class FieldEmbeddings:
    """The ring maps of Q(theta) into F_p, theta the primitive element of an algebraic number field.

    A tableau with radical entries has its weights in a number field K = Q(theta) of degree d
    (sympy's ``QQ.algebraic_field``; None for Q, d = 1). Modulo a prime p at which the minimal
    polynomial of theta splits into d distinct linear factors, each root r gives a ring map
    x = sum_j q_j theta^j -> sum_j q_j r^j (mod p). A computation that is polynomial in such
    numbers with rational coefficients commutes with these maps, so it can run modulo p once per
    root; the d images of a result give back its coordinates q_j modulo p (a Vandermonde system),
    and the coordinates over several primes give the rationals (:func:`crt_pair`,
    :func:`rational_reconstruction`).
    """

    def __init__(self, field=None):
        self.field = field
        if field is None:
            self.degree = 1
            self._minpoly = (1, 0)  # theta = 0: Q itself
        else:
            coeffs = [Fraction(int(c.numerator), int(c.denominator)) for c in field.mod.to_list()]
            den = 1
            for c in coeffs:
                den = den * c.denominator // _gcd(den, c.denominator)
            self.degree = len(coeffs) - 1
            self._minpoly = tuple(int(c * den) for c in coeffs)

    def primes(self, scan: int = 20_000):
        """Yield (p, roots): primes below 2^31, from the largest down, at which the minimal
        polynomial has ``degree`` distinct roots (every prime for Q); at most ``scan`` primes are
        tried (a polynomial of degree d splits at about one prime in d! or fewer)."""
        p = 1 << 31
        for _ in range(scan):
            p = _previous_prime(p)
            roots = self._roots(p)
            if roots is not None:
                yield p, roots

    def _roots(self, p: int):
        if self.field is None:
            return (0,)
        if self._minpoly[0] % p == 0:
            return None
        from sympy import Poly, symbols

        x = symbols("x")
        poly = Poly(list(self._minpoly), x, modulus=p)
        _, factors = poly.factor_list()
        roots = []
        for f, mult in factors:
            if f.degree() != 1 or mult != 1:
                return None
            a, b = (int(c) for c in f.all_coeffs())
            roots.append(-b * pow(a, -1, p) % p)
        return tuple(sorted(roots)) if len(roots) == self.degree else None

    def coordinates(self, x) -> tuple[Fraction, ...]:
        """The rational coordinates (q_0, ..., q_{d-1}) of x in the basis 1, theta, ..., theta^(d-1)."""
        if self.field is None:
            return (Fraction(x),)
        if isinstance(x, (int, Fraction)):
            return (Fraction(x),) + (Fraction(0),) * (self.degree - 1)
        element = x if hasattr(x, "to_list") else self.field.from_sympy(x)
        high_first = [Fraction(int(c.numerator), int(c.denominator)) for c in element.to_list()]
        low_first = high_first[::-1]
        return tuple(low_first) + (Fraction(0),) * (self.degree - len(low_first))

    def images(self, x, p: int, roots) -> tuple[int, ...]:
        """The residues of x under the maps theta -> r, r in ``roots``."""
        q = [to_residue(c, p) for c in self.coordinates(x)]
        return tuple(sum(c * pow(r, j, p) for j, c in enumerate(q)) % p for r in roots)

    def coordinates_mod(self, values, p: int, roots) -> tuple[int, ...]:
        """Coordinates modulo p of the element whose images under ``roots`` are ``values``."""
        if self.field is None:
            return (int(values[0]) % p,)
        V = [[pow(r, j, p) for j in range(self.degree)] + [int(v) % p] for r, v in zip(roots, values)]
        rows, pivots = rref_mod(np.array(V, dtype=np.int64), p)
        if pivots != tuple(range(self.degree)):
            raise ValueError("singular Vandermonde system (repeated roots)")
        return tuple(int(rows[j, -1]) for j in range(self.degree))

    def element(self, coordinates):
        """The exact number with these rational coordinates: a Fraction for Q, else a sympy number."""
        if self.field is None:
            return Fraction(coordinates[0])
        import sympy

        theta = self.field.ext.as_expr() if hasattr(self.field.ext, "as_expr") else self.field.ext
        expr = sum(sympy.Rational(c.numerator, c.denominator) * theta ** j for j, c in enumerate(coordinates))
        expr = sympy.radsimp(sympy.expand(expr))
        return Fraction(int(expr.p), int(expr.q)) if expr.is_Rational else expr


def reconstruct_coordinates(residues: list[tuple[int, ...]], primes: list[int]) -> tuple[Fraction, ...]:
    """Rational coordinates from their residues modulo several primes (CRT, then rational
    reconstruction of each); ValueError when the modulus is still too small."""
    out = []
    for j in range(len(residues[0])):
        value, modulus = residues[0][j], primes[0]
        for res, p in zip(residues[1:], primes[1:]):
            value, modulus = crt_pair(value, modulus, res[j], p), modulus * p
        out.append(rational_reconstruction(value, modulus))
    return tuple(out)


def _gcd(a: int, b: int) -> int:
    return gcd(a, b)


def _previous_prime(n: int) -> int:
    """The largest prime below n (n <= 2^31 + 1)."""
    n -= 1
    while not _is_prime(n):
        n -= 1
    return n


def _is_prime(n: int) -> bool:
    """Miller–Rabin with the bases 2, 3, 5, 7: deterministic below 3,215,031,751 > 2^31."""
    if n < 2:
        return False
    for q in (2, 3, 5, 7):
        if n % q == 0:
            return n == q
    d, r = n - 1, 0
    while d % 2 == 0:
        d, r = d // 2, r + 1
    for a in (2, 3, 5, 7):
        x = pow(a, d, n)
        if x in (1, n - 1):
            continue
        for _ in range(r - 1):
            x = x * x % n
            if x == n - 1:
                break
        else:
            return False
    return True


class Inconsistent(Exception):
    """A linear system of order ``order`` had no solution modulo two primes (an exact finding)."""

    def __init__(self, order: int):
        super().__init__(order)
        self.order = order


def solve_over_primes(compute, keys, embeddings: FieldEmbeddings, seed: int, max_primes: int = 8):
    """Exact coordinates of quantities computed modulo primes (docs/theory.md §8, §11).

    ``compute(p, roots, rng)`` returns, for each key, the residues modulo p of its coordinates in
    the basis 1, theta, ..., theta^(d-1) of the number field, or an int n: the order at which its
    linear system was inconsistent. Primes come from ``embeddings.primes()``, each with its own
    random stream of ``seed``. Returns (coordinates by key, primes used, confirming prime) once
    the reconstruction from all primes but the last agrees with the last. Raises
    :class:`Inconsistent` when two primes report the same inconsistent order, ValueError when
    ``max_primes`` primes do not reconstruct.
    """
    streams = np.random.SeedSequence(seed).spawn(max_primes)
    results: list[tuple[int, dict]] = []
    inconsistent: list[int] = []
    for k, (p, roots) in zip(range(max_primes), embeddings.primes()):
        outcome = compute(p, roots, np.random.default_rng(streams[k]))
        if isinstance(outcome, int):
            inconsistent.append(outcome)
            if len(inconsistent) >= 2 and inconsistent[-1] == inconsistent[-2]:
                raise Inconsistent(outcome)
            continue
        results.append((p, outcome))
        if len(results) < 3:
            continue
        primes = [q for q, _ in results[:-1]]
        try:
            coordinates = {key: reconstruct_coordinates([r[key] for _, r in results[:-1]], primes) for key in keys}
        except ValueError:
            continue
        last_p, last = results[-1]
        if all(tuple(to_residue(c, last_p) for c in coordinates[key]) == last[key] for key in keys):
            return coordinates, primes, last_p
    raise ValueError(f"no reconstruction with {max_primes} primes")
