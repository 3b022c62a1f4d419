"""Constructors for the three families of Poisson systems and their birealisations (docs/theory.md §4).

- Lie–Poisson: pi_ij(x) = sum_k C_ij^k x_k; K(p) with K(p) x = -pi(x) p; alpha = phi(K(p)) x,
  beta = phi(-K(p)) x, phi(z) = z / (1 - e^{-z}) (power series with a guard, |K| < 0.9 * 2 pi).
  On so(3)* the closed form alpha = x + (p x x)/2 + c(|p|^2) p x (p x x) is used instead.
- Log-canonical: pi_ij = lambda_ij x_i x_j, alpha_i = x_i exp(-(1/2) sum_j lambda_ij x_j p_j).
- Constant: alpha = x - pi p / 2, beta = x + pi p / 2.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..errors import InputError
from . import tape as tp
from .core import PoissonSystem, build_system


def _check_antisymmetric(matrix: np.ndarray, what: str) -> None:
    if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1]:
        raise InputError(f"{what} must be a square matrix, got shape {matrix.shape}")
    if not np.all(np.isfinite(matrix)):
        raise InputError(f"{what} has non-finite entries")
    if not np.allclose(matrix, -matrix.T, rtol=0, atol=1e-14 * max(1.0, np.abs(matrix).max())):
        raise InputError(f"{what} is not antisymmetric")


def _combination(k: np.ndarray, term: str) -> str:
    """'k1 TERM1 - k2 TERM2 ...' with the coefficients rounded for display."""
    text = ""
    for i, c in enumerate(k):
        if abs(c) < 1e-12:
            continue
        sign = "-" if c < 0 else "+"
        mag = "" if abs(abs(c) - 1) < 1e-12 else f"{abs(c):.6g} "
        text += f" {sign} {mag}{term}{i + 1}" if text else f"{'-' if c < 0 else ''}{mag}{term}{i + 1}"
    return text


def _linear_kernel(matrix: np.ndarray) -> list[np.ndarray]:
    from scipy.linalg import null_space

    return [v / np.abs(v).max() for v in null_space(matrix).T]


def lie_poisson(structure: np.ndarray, hamiltonian: Callable, *, name: str, x0, t_final: float,
                realisation: str = "symmetric", casimirs=(), casimir_names=(),
                exact_solution=None, description: str = "") -> PoissonSystem:
    """A Lie–Poisson system from structure constants C[i, j, k] ({x_i, x_j} = sum_k C_ijk x_k).

    `hamiltonian(x)` is a program over tape Vars. alpha = phi(K(p)) x by the matrix power series.
    """
    C = np.asarray(structure, dtype=np.float64)
    n = C.shape[0]
    if C.shape != (n, n, n):
        raise InputError(f"structure constants must have shape (n, n, n), got {C.shape}")
    for k in range(n):
        _check_antisymmetric(C[:, :, k], f"structure constants C[:, :, {k + 1}]")

    def poisson(x):
        return np.einsum("ijk,k->ij", C, np.asarray(x, dtype=np.float64))

    def K_of(p, sign):
        # K(p)_ik = -sum_j C_ijk p_j
        return [[sum(-sign * C[i, j, k] * p[j] for j in range(n) if C[i, j, k] != 0.0)
                 for k in range(n)] for i in range(n)]

    def poisson_program(y):
        return [[_linear(C[i, j], y) for j in range(n)] for i in range(n)]

    def base_alpha(x, p):
        return x[0].builder.phimv(K_of(p, 1.0), x)

    def base_beta(x, p):
        return x[0].builder.phimv(K_of(p, -1.0), x)

    return build_system(name=name, family="lie-poisson", dim=n, poisson=poisson,
                        hamiltonian=hamiltonian, base_alpha=base_alpha, base_beta=base_beta,
                        x0=x0, t_final=t_final, poisson_program=poisson_program, poisson_degree=1,
                        realisation_name=realisation, casimirs=casimirs,
                        casimir_names=casimir_names, exact_solution=exact_solution,
                        description=description)


def _linear(coefficients, y):
    """sum_k c_k y_k over the non-zero c_k (0.0 when all vanish)."""
    terms = [y[k] * float(c) for k, c in enumerate(coefficients) if c != 0.0]
    return sum(terms[1:], terms[0]) if terms else 0.0


def so3_matrix(y):
    """pi(y) on so(3)*: pi(y) v = y cross v."""
    return [[0.0, -y[2], y[1]], [y[2], 0.0, -y[0]], [-y[1], y[0], 0.0]]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def so3_alpha(x, p, sign=1.0):
    """alpha = x + (p x x)/2 + c(|p|^2) p x (p x x) on so(3)* (beta: sign = -1; docs/theory.md §4)."""
    px = _cross(p, x)
    ppx = _cross(p, px)
    c = tp.crb(p)
    return [x[i] + (0.5 * sign) * px[i] + c * ppx[i] for i in range(3)]


def so3(hamiltonian: Callable, *, name: str, x0, t_final: float, realisation: str = "symmetric",
        exact_solution=None, description: str = "") -> PoissonSystem:
    """A Lie–Poisson system on so(3)* (pi(x) v = x cross v) with the closed-form realisation."""

    def poisson(x):
        x = np.asarray(x, dtype=np.float64)
        return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])

    return build_system(
        name=name, family="lie-poisson", dim=3, poisson=poisson, hamiltonian=hamiltonian,
        base_alpha=lambda x, p: so3_alpha(x, p, 1.0), base_beta=lambda x, p: so3_alpha(x, p, -1.0),
        x0=x0, t_final=t_final, poisson_program=so3_matrix, poisson_degree=1,
        realisation_name=realisation,
        casimirs=(lambda x: 0.5 * float(np.dot(x, x)),), casimir_names=("|x|^2/2",),
        exact_solution=exact_solution, description=description)


def log_canonical(lam, hamiltonian: Callable, *, name: str, x0, t_final: float,
                  realisation: str = "symmetric", casimirs=None, casimir_names=(),
                  exact_solution=None, description: str = "") -> PoissonSystem:
    """A log-canonical system pi_ij = lambda_ij x_i x_j on the positive orthant.

    Without explicit Casimirs, every kernel vector k of lambda gives C = sum_i k_i log x_i.
    """
    L = np.asarray(lam, dtype=np.float64)
    _check_antisymmetric(L, "lambda")
    n = L.shape[0]

    def poisson(x):
        x = np.asarray(x, dtype=np.float64)
        return L * np.outer(x, x)

    def make(sign):
        def base(x, p):
            out = []
            for i in range(n):
                terms = [(-0.5 * sign * L[i, j]) * (x[j] * p[j]) for j in range(n) if L[i, j]]
                out.append(x[i] * tp.exp(sum(terms[1:], terms[0])) if terms else x[i])
            return out

        return base

    def poisson_program(y):
        return [[y[i] * y[j] * float(L[i, j]) if L[i, j] else 0.0 for j in range(n)]
                for i in range(n)]

    if casimirs is None:
        kernel = _linear_kernel(L)
        casimirs = tuple((lambda x, k=k: float(np.dot(k, np.log(x)))) for k in kernel)
        casimir_names = tuple(_combination(k, "log x") for k in kernel)
    return build_system(name=name, family="log-canonical", dim=n, poisson=poisson,
                        hamiltonian=hamiltonian, base_alpha=make(1.0), base_beta=make(-1.0),
                        x0=x0, t_final=t_final, poisson_program=poisson_program,
                        poisson_degree=2, realisation_name=realisation, domain="positive orthant",
                        casimirs=casimirs, casimir_names=casimir_names,
                        exact_solution=exact_solution, description=description)


def constant(pi, hamiltonian: Callable, *, name: str, x0, t_final: float,
             realisation: str = "symmetric", casimirs=None, casimir_names=(),
             exact_solution=None, description: str = "") -> PoissonSystem:
    """A system with a constant Poisson matrix; linear Casimirs k.x from the kernel of pi."""
    P = np.asarray(pi, dtype=np.float64)
    _check_antisymmetric(P, "poisson")
    n = P.shape[0]

    def make(sign):
        def base(x, p):
            return [x[i] + sum((-0.5 * sign * P[i, j]) * p[j] for j in range(n) if P[i, j])
                    for i in range(n)]

        return base

    if casimirs is None:
        kernel = _linear_kernel(P)
        casimirs = tuple((lambda x, k=k: float(np.dot(k, x))) for k in kernel)
        casimir_names = tuple(_combination(k, "x") for k in kernel)
    return build_system(name=name, family="constant", dim=n, poisson=lambda x: P.copy(),
                        hamiltonian=hamiltonian, base_alpha=make(1.0), base_beta=make(-1.0),
                        x0=x0, t_final=t_final,
                        poisson_program=lambda y: [[float(v) for v in row] for row in P],
                        poisson_degree=0, realisation_name=realisation, casimirs=casimirs,
                        casimir_names=casimir_names, exact_solution=exact_solution,
                        description=description)
