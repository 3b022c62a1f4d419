"""The points of a Lie–Poisson substep in direct form (`rkhp.integrators.closed_euler`): from z,
with K = K(z) (K(p) x = -pi(x) p, docs/theory.md §4), y1 - y0 = e^-K y0 - y0 and x = psi(K) y0,
psi(z) = (1 - e^-z) / z.

e^-K y0 and psi(K) y0 are the power series sum_m (-K)^m y0 / m! and sum_m (-K)^m y0 / (m + 1)!
by products with K stored by its non-zero entries (O(nnz(C)) a product, `exp_series`), under the
guard of the family's phi (|K|_F < 0.9 * 2 pi, `rkhp.taylor.composites.phimv`): a substep beyond
it fails as the engine's Newton iteration does on the NaN that phi gives there
(NEWTON_NON_FINITE). On so(3)* they are Rodrigues' closed forms (`rotation_point`), with the
Jacobian of x in z (`rotation_jacobian`).

On a diagonal algebra K(p) reads x only through the coordinates A of its non-zero columns and is
diagonal on them: K = [[D, 0], [E, 0]] in the split (A, the rest), D = diag(d) (the periodic
Toda lattice in Flaschka's variables). Then K^m = [[D^m, 0], [E D^(m-1), 0]], so with a = y0 on A
and w = -d, phi_k(w) = sum_m w^m / (m + k)! componentwise (docs/theory.md §4):
e^-K y0 - y0 = (w phi_1(w) a, -E phi_1(w) a) and psi(K) y0 = (phi_1(w) a, y0 - E phi_2(w) a) on
(A, the rest): closed forms of |A| exponentials (`diagonal_point`). Its loops over K's sparse
entries cost more than their arithmetic, so the same point is also written out per algebra as
plain arithmetic, K's entries and the pairs' products unrolled and phi_2's series summed for all
columns at once (`diagonal_point_source`), and compiled as a `cfunc` (`diagonal_point_at`,
`rkhp.taylor.generated`, docs/engine.md "Derivatives compiled per system"), bit for bit the same
values as `diagonal_point`, which serves where the module cannot be kept or the algebra has more
than POINT_ENTRIES entries.

On se(3)* (the heavy top), x = (M, Gamma) and K = [[hat(q), hat(r)], [0, hat(q)]] with (q, r) =
s p: a function of a block triangular matrix with equal diagonal blocks is f(K) = [[f(hat q),
Df(hat q)[hat r]], [0, f(hat q)]], Df the derivative along hat(r), and f(hat q) = I + beta hat(q)
+ gamma hat(q)^2 with beta, gamma functions of theta = |q| (Rodrigues'), so that Df(hat q)[hat r]
= (q . r)(beta'/theta hat(q) + gamma'/theta hat(q)^2) + beta hat(r) + gamma (hat(q) hat(r) +
hat(r) hat(q)): closed forms in cross products (`se3_point`, docs/theory.md §4).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..taylor import generated
from ..taylor.compiler import NJIT_NORC
from ..taylor.compiler import numba as nb
from ..taylor.elementary import TWO_PI
from ..taylor.generated import call_at
from .failure import Failure

PHI_GUARD = 0.9 * TWO_PI
"""The bound on |K|_F of the family's phi (`rkhp.taylor.composites.phimv`), kept here so that
the direct form fails where the engine does."""
SERIES_TERMS = 64
"""Terms of the series of e^-K at most (|K|_F < PHI_GUARD needs about 40 for round-off)."""
ROTATION_SERIES = 1.0
"""Below this angle theta the coefficients of the rotation (`_rotation_coefficients`) are summed
as their power series (ROTATION_TERMS terms: the next is below 2^-56 of the first), above it
taken from sin and cos (whose differences lose at most a few units of round-off there)."""
ROTATION_TERMS = 9
PHI_SERIES = 1.0
"""Below this |w| the functions phi_1, phi_2 of `diagonal_point` are summed as the power series of
phi_2 (as many terms as leave the next below 2^-56 of the first, `PHI_REACH`: PHI_TERMS at
|w| near 1) with phi_1 = 1 + w phi_2; above it phi_1 = expm1(w) / w and phi_2 = (phi_1 - 1) / w
(at |w| = 1 the difference loses at most a factor 3 of round-off)."""
PHI_TERMS = 18
PHI_TABLE = np.array([1.0 / math.factorial(m + 2) for m in range(PHI_TERMS)])
"""1 / (m + 2)!, the coefficients of phi_2's series."""
PHI_REACH = np.array([0.0] + [(math.factorial(t + 2) * 2.0**-57) ** (1.0 / t) for t in range(1, PHI_TERMS + 1)])
"""PHI_REACH[t]: the largest |w| at which t terms of phi_2's series leave the next,
|w|^t / (t + 2)!, below 2^-56 of the first (1/2): 9 terms up to |w| = 0.087, 6 up to 0.0081;
PHI_REACH[PHI_TERMS] > PHI_SERIES."""
POINT_CONSTANTS = np.concatenate([PHI_TABLE, PHI_REACH])
"""What the generated point reads after z and y0 in its input (`diagonal_point_source`)."""
POINT_ENTRIES = 128
"""The most entries of K whose point is generated (toda:64 has 96; its module compiles in a few
seconds, once per machine): beyond, `diagonal_point` interprets them."""
GENERATOR = Path(__file__).resolve()
"""The source that writes the generated point (its content is part of the module's key)."""


def _rotation_series_table() -> np.ndarray:
    """The coefficients in t = theta^2 of `_rotation_coefficients`' five series: (-1)^m / (2 m +
    k)! for k = 1, 2, 3 (sin theta / theta, (1 - cos theta) / theta^2, (theta - sin theta) /
    theta^3), then (-1)^(m + 1) 2 (m + 1) / (2 m + k + 2)! for k = 2, 3 (their derivatives in
    theta, divided by theta)."""
    table = np.zeros((5, ROTATION_TERMS))
    for m in range(ROTATION_TERMS):
        for row, k in enumerate((1, 2, 3)):
            table[row, m] = (-1) ** m / math.factorial(2 * m + k)
        for row, k in ((3, 2), (4, 3)):
            table[row, m] = (-1) ** (m + 1) * 2 * (m + 1) / math.factorial(2 * m + k + 2)
    return table


ROTATION_SERIES_TABLE = _rotation_series_table()


@nb.njit(inline="always", **NJIT_NORC)
def _k_entries(form, work):
    """K(work.z)'s entries into work.kval; returns |K|_F."""
    norm = 0.0
    for e in range(form.pairs.shape[0]):
        acc = 0.0
        for r in range(form.starts[e], form.starts[e + 1]):
            acc += form.coefs[r] * work.z[form.cols[r]]
        work.kval[e] = acc
        norm += acc * acc
    return math.sqrt(norm)


@nb.njit(inline="always", **NJIT_NORC)
def exp_series(y0, form, work, n):
    """Lie-poisson: K(work.z) into work.kval, then work.dy := e^-K y0 - y0 and work.xbar :=
    psi(K) y0 by their power series (see the module), summed until the next terms' bound is
    below round-off. Returns Failure.OK, or NEWTON_NON_FINITE when |K|_F is not below PHI_GUARD
    (or not finite)."""
    norm = _k_entries(form, work)
    if not norm < PHI_GUARD:
        return Failure.NEWTON_NON_FINITE
    size0 = 0.0
    for k in range(n):
        work.v[k] = y0[k]
        work.dy[k] = 0.0
        work.xbar[k] = y0[k]
        size0 += y0[k] * y0[k]
    bound = 2.0**-106 * size0  # (2^-53 |y0|_2)^2
    for m in range(1, SERIES_TERMS + 1):
        for k in range(n):
            work.kv[k] = 0.0
        for e in range(form.pairs.shape[0]):
            work.kv[form.pairs[e, 0]] -= work.kval[e] * work.v[form.pairs[e, 1]]
        size = 0.0
        for k in range(n):
            t = work.kv[k] / m
            work.v[k] = t
            work.dy[k] += t
            work.xbar[k] += t / (m + 1)
            size += t * t
        # the tail after term m is at most |v_m|_2 q / (1 - q) <= |v_m|_2, q = |K|_2 / (m + 1)
        if 2.0 * norm <= m + 1 and size <= bound:
            return Failure.OK
    return Failure.NEWTON_NON_FINITE


@nb.njit(inline="always", **NJIT_NORC)
def _series(t, row):
    """sum_m ROTATION_SERIES_TABLE[row, m] t^m by Horner's rule."""
    acc = 0.0
    for m in range(ROTATION_TERMS - 1, -1, -1):
        acc = acc * t + ROTATION_SERIES_TABLE[row, m]
    return acc


@nb.njit(inline="always", **NJIT_NORC)
def _rotation_coefficients(theta):
    """(sin(theta) / theta, (1 - cos theta) / theta^2, (theta - sin theta) / theta^3, a'/theta,
    b'/theta), a and b the second and third (their derivatives in theta divided by theta, for the
    Jacobian `rotation_jacobian`): power series below ROTATION_SERIES (the singularities at 0 are
    removable), sin and cos above."""
    if theta < ROTATION_SERIES:
        t = theta * theta
        return _series(t, 0), _series(t, 1), _series(t, 2), _series(t, 3), _series(t, 4)
    s = math.sin(theta)
    t2 = theta * theta
    half = math.sin(0.5 * theta)
    one_minus_cos = 2.0 * half * half
    return (s / theta, one_minus_cos / t2, (theta - s) / (t2 * theta),
            (theta * s - 2.0 * one_minus_cos) / (t2 * t2),
            (theta * one_minus_cos - 3.0 * (theta - s)) / (t2 * t2 * theta))


@nb.njit(inline="always", **NJIT_NORC)
def _cross(a, b, out):
    """out := a x b (3-vectors)."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@nb.njit(inline="always", **NJIT_NORC)
def rotation_point(y0, form, work):
    """so(3)*: with q = s z (K = hat(q), K y = q x y, theta = |q|), Rodrigues' closed forms
    e^-K y0 = y0 - (sin theta / theta) q x y0 + ((1 - cos theta) / theta^2) q x (q x y0) and
    psi(K) y0 = y0 - ((1 - cos theta) / theta^2) q x y0 + ((theta - sin theta) / theta^3) q x (q x y0)
    (the series of the module summed by K^3 = -theta^2 K: docs/theory.md §12). work.v := q,
    work.kv := q x y0, work.tmp := q x (q x y0); Failure as `exp_series` (|K|_F = sqrt(2) theta)."""
    q, c1, c2 = work.v, work.kv, work.tmp
    for k in range(3):
        q[k] = form.rotation * work.z[k]
    theta = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    if not math.sqrt(2.0) * theta < PHI_GUARD:
        return Failure.NEWTON_NON_FINITE
    sinc, a, b, _, _ = _rotation_coefficients(theta)
    _cross(q, y0, c1)
    _cross(q, c1, c2)
    for k in range(3):
        work.dy[k] = -sinc * c1[k] + a * c2[k]
        work.xbar[k] = y0[k] - a * c1[k] + b * c2[k]
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def rotation_jacobian(y0, form, work, D):
    """D := x'(z) on so(3)*, x = y0 - a c1 + b c2 (`rotation_point`, c1 = q x y0, c2 = q x c1,
    q = s z): d c1 / dq = -hat(y0), d c2 / dq = (q . y0) I + q y0^T - 2 y0 q^T, d a / dq =
    (a'/theta) q^T, d b / dq = (b'/theta) q^T; then times s. Reads what `rotation_point` left in
    work.v, work.kv, work.tmp."""
    q, c1, c2 = work.v, work.kv, work.tmp
    theta = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    _, a, b, da, db = _rotation_coefficients(theta)
    qy = q[0] * y0[0] + q[1] * y0[1] + q[2] * y0[2]
    for i in range(3):
        for j in range(3):
            hat = 0.0  # hat(y0)_ij = -epsilon_ijk y0_k: hat(y0) w = y0 x w
            if (i + 1) % 3 == j:
                hat = -y0[3 - i - j]
            elif (j + 1) % 3 == i:
                hat = y0[3 - i - j]
            d2 = (qy if i == j else 0.0) + q[i] * y0[j] - 2.0 * y0[i] * q[j]
            D[i, j] = form.rotation * ((-c1[i] * da + c2[i] * db) * q[j] + a * hat + b * d2)


@nb.njit(inline="always", **NJIT_NORC)
def _phi_terms(largest):
    """The fewest terms of phi_2's series enough for every |w| <= largest < PHI_SERIES
    (`PHI_REACH`)."""
    terms = 1
    while largest > PHI_REACH[terms]:
        terms += 1
    return terms


@nb.njit(inline="always", **NJIT_NORC)
def _phi_functions(w, terms):
    """(phi_1(w), phi_2(w)), phi_k(w) = sum_m w^m / (m + k)!: below PHI_SERIES the series, `terms`
    terms of phi_2's (`_phi_terms`; the singularities of (e^w - 1) / w and (e^w - 1 - w) / w^2 at
    0 are removable), else phi_1 = expm1(w) / w and phi_2 = (phi_1 - 1) / w."""
    if abs(w) < PHI_SERIES:
        p2 = 0.0
        for m in range(terms - 1, -1, -1):
            p2 = p2 * w + PHI_TABLE[m]
        return 1.0 + w * p2, p2
    p1 = math.expm1(w) / w
    return p1, (p1 - 1.0) / w


@nb.njit(inline="always", **NJIT_NORC)
def diagonal_point(y0, form, work, n):
    """A diagonal algebra (see the module; form.diagonal[k] the entry of K_kk, or -1): work.dy :=
    e^-K y0 - y0 and work.xbar := psi(K) y0 in closed form from K(work.z)'s entries (work.kval);
    work.kv := phi_1(-K_kk) and work.tmp := phi_2(-K_kk) per column k (1 and 1/2 where K_kk
    vanishes). The series of the entries below PHI_SERIES take the terms their largest needs
    (`_phi_terms`). Failure as `exp_series`."""
    norm = _k_entries(form, work)
    if not norm < PHI_GUARD:
        return Failure.NEWTON_NON_FINITE
    largest = 0.0
    for k in range(n):
        e = form.diagonal[k]
        if e >= 0 and abs(work.kval[e]) < PHI_SERIES:
            largest = max(largest, abs(work.kval[e]))
    terms = _phi_terms(largest)
    p1, p2 = work.kv, work.tmp
    for k in range(n):
        p1[k] = 1.0
        p2[k] = 0.5
        work.dy[k] = 0.0
        work.xbar[k] = y0[k]
        e = form.diagonal[k]
        if e >= 0:
            w = -work.kval[e]
            p1[k], p2[k] = _phi_functions(w, terms)
            work.dy[k] = w * p1[k] * y0[k]
            work.xbar[k] = p1[k] * y0[k]
    for e in range(form.pairs.shape[0]):
        i, k = form.pairs[e, 0], form.pairs[e, 1]
        if i != k:
            work.dy[i] -= work.kval[e] * p1[k] * y0[k]
            work.xbar[i] -= work.kval[e] * p2[k] * y0[k]
    return Failure.OK


def diagonal_point_source(pairs, starts, cols, coefs, diagonal, n: int) -> str:
    """The body ``def point(u, out, what)`` of the generated point of a diagonal algebra whose K
    has the entries (pairs, starts, cols, coefs) and the diagonal `diagonal` (as
    `rkhp.integrators.closed_euler.ClosedForm`): from u = (z, y0, POINT_CONSTANTS) it writes
    out = (e^-K y0 - y0, psi(K) y0, 0), or 1 in out[2n] beyond phi's guard; the same operations
    in the same order as `diagonal_point`, so the same values bit for bit (phi_2's series summed
    with the terms its largest entry needs, for all columns at once: each column's own Horner
    chain, as `_phi_functions` sums it)."""
    entries, table, reach = pairs.shape[0], 2 * n, 2 * n + PHI_TABLE.size
    lines = ["def point(u, out, what):"]
    for e in range(entries):
        terms = "".join(f" + {float(coefs[r])!r} * u[{int(cols[r])}]" for r in range(starts[e], starts[e + 1]))
        lines.append(f"    k{e} = 0.0{terms}")
    lines += ["    norm = 0.0" + "".join(f" + k{e} * k{e}" for e in range(entries)),
              f"    if not math.sqrt(norm) < {PHI_GUARD!r}:", f"        out[{2 * n}] = 1.0", "        return",
              f"    out[{2 * n}] = 0.0", "    largest = 0.0"]
    columns = [(k, int(diagonal[k])) for k in range(n) if diagonal[k] >= 0]
    for k, e in columns:
        lines += [f"    w{k} = -k{e}", f"    if abs(w{k}) < {PHI_SERIES!r}:",
                  f"        largest = max(largest, abs(w{k}))"]
    lines += ["    terms = 1", f"    while largest > u[{reach} + terms]:", "        terms += 1"]
    lines += [f"    q{k} = 0.0" for k, _ in columns]
    lines += ["    m = terms - 1", "    while m >= 0:", f"        c = u[{table} + m]"]
    lines += [f"        q{k} = q{k} * w{k} + c" for k, _ in columns]
    lines += ["        m -= 1"]
    for k in range(n):
        if diagonal[k] >= 0:
            lines += [f"    if abs(w{k}) < {PHI_SERIES!r}:", f"        p{k} = 1.0 + w{k} * q{k}", "    else:",
                      f"        p{k} = math.expm1(w{k}) / w{k}", f"        q{k} = (p{k} - 1.0) / w{k}",
                      f"    d{k} = w{k} * p{k} * u[{n + k}]", f"    x{k} = p{k} * u[{n + k}]"]
        else:
            lines += [f"    p{k} = 1.0", f"    q{k} = 0.5", f"    d{k} = 0.0", f"    x{k} = u[{n + k}]"]
    for e in range(entries):
        i, k = int(pairs[e, 0]), int(pairs[e, 1])
        if i != k:
            lines += [f"    d{i} -= k{e} * p{k} * u[{n + k}]", f"    x{i} -= k{e} * q{k} * u[{n + k}]"]
    for k in range(n):
        lines += [f"    out[{k}] = d{k}", f"    out[{n + k}] = x{k}"]
    return "\n".join(lines) + "\n"


def diagonal_point_at(pairs, starts, cols, coefs, diagonal, n: int) -> int:
    """The address of the generated point of a diagonal algebra (`diagonal_point_source`), its
    module keyed by the entries, the dimension and this source; 0 beyond POINT_ENTRIES or where the
    module cannot be kept."""
    if pairs.shape[0] > POINT_ENTRIES:
        return 0
    arrays = (np.ascontiguousarray(pairs, dtype=np.int64), np.ascontiguousarray(starts, dtype=np.int64),
              np.ascontiguousarray(cols, dtype=np.int64), np.ascontiguousarray(coefs, dtype=np.float64),
              np.ascontiguousarray(diagonal, dtype=np.int64))
    key = generated.key_of(b"diagonal point", *(a.tobytes() for a in arrays), f"{n}".encode(), GENERATOR.read_bytes())
    return generated.compiled_address(key, "point", lambda: diagonal_point_source(*arrays, n))


@nb.njit(inline="always", **NJIT_NORC)
def generated_diagonal_point(y0, form, work, n):
    """`diagonal_point` by the generated point at form.point_at (`diagonal_point_at`): z and y0
    into work.zy (after them POINT_CONSTANTS, set once), the point into work.pt, then work.dy and
    work.xbar from it. Failure as `diagonal_point`."""
    for k in range(n):
        work.zy[k] = work.z[k]
        work.zy[n + k] = y0[k]
    call_at(form.point_at, work.zy, work.pt, 0)
    if work.pt[2 * n] != 0.0:
        return Failure.NEWTON_NON_FINITE
    for k in range(n):
        work.dy[k] = work.pt[k]
        work.xbar[k] = work.pt[n + k]
    return Failure.OK


@nb.njit(inline="always", **NJIT_NORC)
def se3_point(y0, form, work):
    """se(3)*: x = (M, Gamma), with q = s z_1..3 and r = s z_4..6, K = [[hat(q), hat(r)], [0,
    hat(q)]] (see the module): f(K) y0 = (f(hat q) M + Df(hat q)[hat r] Gamma, f(hat q) Gamma) for
    f(K) = e^-K and psi(K), f(hat q) = I + beta hat(q) + gamma hat(q)^2 as in `rotation_point`, and
    its derivative along r, Df[hat r] = (q . r) (beta'/theta hat(q) + gamma'/theta hat(q)^2) +
    beta hat(r) + gamma (hat(q) hat(r) + hat(r) hat(q)). Failure as `exp_series` (|K|_F^2 =
    4 theta^2 + 2 |r|^2). Work: work.v, work.kv, work.tmp, work.xz, work.by hold q, r and the
    products (none of them is read across a point by `rkhp.integrators.closed_euler`)."""
    q, r, c1, c2, e1 = work.v, work.kv, work.tmp, work.xz, work.by
    for k in range(3):
        q[k] = form.rotation * work.z[k]
        r[k] = form.rotation * work.z[3 + k]
    theta2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2]
    rr = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    if not math.sqrt(4.0 * theta2 + 2.0 * rr) < PHI_GUARD:
        return Failure.NEWTON_NON_FINITE
    sinc, a, b, da, db = _rotation_coefficients(math.sqrt(theta2))
    qr = q[0] * r[0] + q[1] * r[1] + q[2] * r[2]
    # Gamma's parts: c1 = q x G, c2 = q x c1; e1 = r x G, then the symmetric products
    _cross(q, y0[3:], c1)
    _cross(q, c1, c2)
    _cross(r, y0[3:], e1)
    for k in range(3):
        work.dy[3 + k] = -sinc * c1[k] + a * c2[k]
        work.xbar[3 + k] = y0[3 + k] - a * c1[k] + b * c2[k]
    # coupling: (q . r)(beta'/theta c1 + gamma'/theta c2) + beta e1 + gamma (q x e1 + r x c1);
    # e^-K: beta = -sinc (beta'/theta = a - b), gamma = a; psi: beta = -a, gamma = b
    for k in range(3):
        work.dy[k] = qr * ((a - b) * c1[k] + da * c2[k]) - sinc * e1[k]
        work.xbar[k] = qr * (-da * c1[k] + db * c2[k]) - a * e1[k]
    _cross(q, e1, c2)  # q x (r x G); q x (q x G) is no longer needed
    _cross(r, c1, e1)  # r x (q x G); r x G is no longer needed
    for k in range(3):
        sym = c2[k] + e1[k]
        work.dy[k] += a * sym
        work.xbar[k] += b * sym
    # M's own part
    _cross(q, y0[:3], c1)
    _cross(q, c1, c2)
    for k in range(3):
        work.dy[k] += -sinc * c1[k] + a * c2[k]
        work.xbar[k] += y0[k] - a * c1[k] + b * c2[k]
    return Failure.OK
