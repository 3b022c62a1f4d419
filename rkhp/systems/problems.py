"""Reference problems of the field (docs/theory.md §9), each with its source.

Convention of docs/theory.md §4: xdot = pi(x) grad H(x), pi_ij = {x_i, x_j}. Every problem is
described once, as expressions (:class:`ProblemData`: pi, H, Casimirs, x0, t_final), and built in
its family: the closed-form families (Lie–Poisson, log-canonical) where pi is linear or
log-canonical, the ``general`` family (the spray realisation) otherwise; :func:`as_general` builds
any of them in the general family (for comparisons). Reference solutions: `rkhp.studies.reference`
(DOP853 at tight tolerance, its error estimated by a second solve); tests/test_problems.py compares
them with the values the sources publish (point vortices, Lotka–Volterra 4d) and with mpmath.

- ``charged-particle``: GeometricProblems.jl, MasslessChargedParticle (JuliaGNI, v0.8.2).
- ``point-vortices``: GeometricProblems.jl, PointVortices (the non-linear, "deformed" model).
- ``nambu``: a Nambu system pi v = grad C x v (Nambu, Phys. Rev. D 7, 2405, 1973).
- ``heavy-top``: the heavy top, Lie–Poisson on se(3)* (Marsden & Ratiu, Introduction to
  Mechanics and Symmetry, 1999; Holm, Marsden, Ratiu & Weinstein, Phys. Rep. 123, 1985).
- ``toda``: the periodic Toda lattice in Flaschka's variables (Flaschka, Phys. Rev. B 9, 1924,
  1974; Toda 1967), size n = 2N a parameter (``toda:12``).
- ``volterra-lattice``: the periodic Volterra (Kac–van Moerbeke) lattice, log-canonical
  (Kac & van Moerbeke, Adv. Math. 16, 160, 1975; Suris, The Problem of Integrable
  Discretization, 2003), size a parameter (``volterra-lattice:7``).
- ``lotka-volterra-4d``: GeometricProblems.jl, LotkaVolterra4d.
- ``lv5-integrable``: 5 species, integrable: the periodic Kac–van Moerbeke lattice with
  Volterra's Hamiltonian sum (x_i - log x_i) (Volterra 1931; Kac & van Moerbeke 1975).
- ``lv5-nonintegrable``: 5 species, lambda_ij = sign(j - i), H = sum (x_i - log x_i):
  the class of Christodoulidi, Hone & Kouloukas (J. Comput. Dyn. 6, 223, 2019) without its
  integrability conditions. The two 5-d systems stand for the integrable and the non-integrable
  Lotka–Volterra systems of Cosserat, arXiv 2511.14303.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..base.bounds import MAX_DIMENSION
from ..base.errors import InputError
from ..base.expressions import parse_expression, variable_names
from .core import PoissonSystem
from .families import GENERAL, LIE_POISSON, LOG_CANONICAL, LieAlgebra, family_system
from .general import PoissonMatrix
from .general import general as general_family
from .program import numeric_function, to_program
from .structure import lie_poisson_matrix, log_canonical_matrix, symbols_of


@dataclass(frozen=True)
class ProblemData:
    """A problem as expressions in x1..xn: `poisson` (n x n strings; None for the lie-poisson
    and log-canonical families, whose pi `poisson_text` writes from `constants`), `hamiltonian`,
    `casimirs` (strings) with display names, the default x0 and t_final, its description and its
    family: "general", or "lie-poisson" / "log-canonical" with the structure constants
    C[i, j, k] / the matrix lambda in `constants`."""

    name: str
    poisson: tuple | None
    hamiltonian: str
    casimirs: tuple
    casimir_names: tuple
    x0: tuple
    t_final: float
    description: str
    family: str = GENERAL
    constants: np.ndarray | None = None

    @property
    def dim(self) -> int:
        return len(self.x0)

    def poisson_text(self) -> tuple:
        """pi as n x n strings: `poisson`, or written from the constants of a lie-poisson
        (pi_ij = sum_k C[i, j, k] x_k) or log-canonical (pi_ij = lambda_ij x_i x_j) problem."""
        if self.poisson is not None:
            return self.poisson
        if self.family == LIE_POISSON:
            return _matrix_text(lie_poisson_matrix(self.constants))
        return _matrix_text(log_canonical_matrix(self.constants))


def _read_expressions(texts, n: int, where: str):
    return tuple(parse_expression(t, variable_names(n), where=where) for t in texts)


def expressions(data: ProblemData):
    """(pi, H, Casimirs) of a problem as sympy expressions in the real symbols x1..xn."""
    H, casimirs = _functions(data)
    return _poisson_entries(data), H, casimirs


def _poisson_entries(data: ProblemData) -> tuple:
    """pi of a problem as sympy expressions."""
    return tuple(_read_expressions(row, data.dim, f"{data.name}: poisson") for row in data.poisson_text())


def _functions(data: ProblemData):
    """(H, Casimirs) of a problem as sympy expressions."""
    (H,) = _read_expressions([data.hamiltonian], data.dim, f"{data.name}: hamiltonian")
    return H, _read_expressions(data.casimirs, data.dim, f"{data.name}: casimirs")


def _matrix_text(entries) -> tuple:
    return tuple(tuple(str(e) for e in row) for row in entries)


# ----------------------------------------------------------------------------------------------
# the problems


def charged_particle() -> ProblemData:
    """Massless charged particle in the plane (GeometricProblems.jl, MasslessChargedParticle,
    A0 = E0 = 1): B(x) = 1 + 2 x1^2 + 2 x2^2, H = phi = cos x1 + sin x2, x0 = (1, 1).

    The source's vector field is the E x B drift xdot = (E2, -E1) / B with E = -grad phi, i.e.
    xdot = (1/B) [[0, -1], [1, 0]] grad phi (its test checks Omega v = -grad H with
    Omega_12 = -B; an older version had the opposite, time-reversed sign). In our convention
    pi = (1/B) [[0, -1], [1, 0]]. No Casimir (pi is non-degenerate).
    """
    b = "(1 + 2*x1^2 + 2*x2^2)"
    return ProblemData("charged-particle", (("0", f"-1/{b}"), (f"1/{b}", "0")),
                       "cos(x1) + sin(x2)", (), (), (1.0, 1.0), 10.0,
                       "massless charged particle, B = 1 + 2|x|^2, H = cos x1 + sin x2 "
                       "(GeometricProblems.jl)")


def point_vortices() -> ProblemData:
    """Two point vortices in the deformed plane (GeometricProblems.jl, PointVortices, the
    non-linear model): gamma1 = gamma2 = 1/2, S(x, y) = 1 + x^2 + y^2, S2 = 1 + 2x^2 + 2y^2,
    H = gamma1 gamma2 S(q1, q2) S(q3, q4) log((q1 - q3)^2 + (q2 - q4)^2) / (2 pi),
    xdot_1 = -H_2 / (gamma1 S2(q1, q2)), xdot_2 = H_1 / (gamma1 S2(q1, q2)) (and the same for
    q3, q4): pi is block-diagonal with blocks (1 / (gamma S2)) [[0, -1], [1, 0]].
    x0 = (0.5, 0.1, 0.5, -0.1), T = 10 (the source's dt = 0.01, nt = 1000). No Casimir
    (pi is non-degenerate; the angular momentum is a first integral, not a Casimir).
    """
    s12, s34 = "(1/2*(1 + 2*x1^2 + 2*x2^2))", "(1/2*(1 + 2*x3^2 + 2*x4^2))"
    rows = (("0", f"-1/{s12}", "0", "0"), (f"1/{s12}", "0", "0", "0"),
            ("0", "0", "0", f"-1/{s34}"), ("0", "0", f"1/{s34}", "0"))
    H = "(1 + x1^2 + x2^2)*(1 + x3^2 + x4^2)*log((x1 - x3)^2 + (x2 - x4)^2)/(8*pi)"
    return ProblemData("point-vortices", rows, H, (), (), (0.5, 0.1, 0.5, -0.1), 10.0,
                       "two point vortices, deformed plane (GeometricProblems.jl)")


def nambu() -> ProblemData:
    """A Nambu system on R^3: pi(x) v = grad C(x) x v, so xdot = grad C x grad H (Nambu 1973),
    Poisson for every C, with C a Casimir; pi_ik = eps_ijk d_j C.

    C = (x1^2 + x2^2)/2 + x3^4/4 and the rigid body's H (I = (2, 1, 2/3)), x0 as the rigid body.
    Why this C: it is not quadratic, so pi (the first derivatives of C, here of degree 3) is not
    linear and no closed-form realisation applies; C is coercive, so its level sets are compact
    and the orbits (C = const, H = const) are closed curves; with x3^2/2 instead of x3^4/4 it is
    the rigid body on so(3)*.
    """
    g = ("x1", "x2", "x3^3")  # grad C
    rows = (("0", f"-{g[2]}", g[1]), (g[2], "0", f"-{g[0]}"), (f"-{g[1]}", g[0], "0"))
    C = "(x1^2 + x2^2)/2 + x3^4/4"
    return ProblemData("nambu", rows, "x1^2/4 + x2^2/2 + 3*x3^2/4", (C,), (C,),
                       (math.cos(1.1), 0.0, math.sin(1.1)), 10.0,
                       "Nambu system, pi v = grad C x v, C = (x1^2 + x2^2)/2 + x3^4/4, "
                       "rigid-body H")


def _eps(i: int, j: int, k: int) -> float:
    return float((i - j) * (j - k) * (k - i) / 2)


def heavy_top() -> ProblemData:
    """The heavy top on se(3)*, x = (M, Gamma) (Marsden & Ratiu 1999; Holm et al. 1985):
    {M_i, M_j} = -eps_ijk M_k, {M_i, Gamma_j} = -eps_ijk Gamma_k, {Gamma_i, Gamma_j} = 0 (the
    rigid body's sign, pi(x) v = x x v on so(3)*), H = sum M_i^2 / (2 I_i) + Gamma_3 (m g l = 1,
    centre of mass on the body's third axis): Mdot = M x Omega + Gamma x e3,
    Gammadot = Gamma x Omega, Omega = I^-1 M. I = (2, 1, 2/3), M0 = (cos 1.1, 0, sin 1.1),
    Gamma0 = (0.6, 0, 0.8). Casimirs |Gamma|^2 and M . Gamma.
    """
    C = np.zeros((6, 6, 6))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                e = _eps(i, j, k)
                if e:
                    C[i, j, k] = -e
                    C[i, 3 + j, 3 + k] = -e
                    C[3 + j, i, 3 + k] = e
    return ProblemData("heavy-top", None, "x1^2/4 + x2^2/2 + 3*x3^2/4 + x6",
                       ("x4^2 + x5^2 + x6^2", "x1*x4 + x2*x5 + x3*x6"), ("|Gamma|^2", "M . Gamma"),
                       (math.cos(1.1), 0.0, math.sin(1.1), 0.6, 0.0, 0.8), 10.0,
                       "heavy top, se(3)*, I = (2, 1, 2/3), m g l = 1", LIE_POISSON, C)


def toda(n: int = 6) -> ProblemData:
    """The periodic Toda lattice with N = n/2 particles in Flaschka's variables
    x = (a_1..a_N, b_1..b_N) (Flaschka 1974; Toda 1967): {a_i, b_i} = -a_i,
    {a_i, b_(i+1)} = a_i (b_(N+1) = b_1), linear (Lie–Poisson); H = sum a_i^2 + sum b_i^2 / 2
    gives Flaschka's equations a_i' = a_i (b_(i+1) - b_i), b_i' = 2 (a_i^2 - a_(i-1)^2).
    Casimirs sum b_i and prod a_i. x0: a_i = 1/2 + cos(2 pi i / N) / 10,
    b_i = sin(2 pi i / N) / 5.
    """
    if isinstance(n, bool) or not (isinstance(n, int) and n >= 6 and n % 2 == 0):
        raise InputError(f"toda: the size must be an even integer n >= 6, got {n!r}")
    N = n // 2
    C = np.zeros((n, n, n))
    for i in range(N):
        for j, value in ((N + i, -1.0), (N + (i + 1) % N, 1.0)):
            C[i, j, i] += value
            C[j, i, i] -= value
    i = np.arange(1, N + 1)
    x0 = np.concatenate([0.5 + 0.1 * np.cos(2 * np.pi * i / N), 0.2 * np.sin(2 * np.pi * i / N)])
    H = " + ".join([f"x{k}^2" for k in range(1, N + 1)] + [f"x{k}^2/2" for k in range(N + 1, n + 1)])
    return ProblemData("toda" if n == 6 else f"toda:{n}", None, H,
                       (" + ".join(f"x{k}" for k in range(N + 1, n + 1)),
                        "*".join(f"x{k}" for k in range(1, N + 1))),
                       ("b_1 + ... + b_N", "a_1 ... a_N"), tuple(float(v) for v in x0), 10.0,
                       f"periodic Toda lattice, Flaschka variables, N = {N} (n = {n})",
                       LIE_POISSON, C)


def volterra_lattice(n: int = 5) -> ProblemData:
    """The periodic Volterra lattice u_i' = u_i (u_(i+1) - u_(i-1)) (Kac & van Moerbeke 1975;
    Suris 2003): log-canonical {u_i, u_(i+1)} = u_i u_(i+1) (indices mod n), H = sum u_i.
    Casimirs sum log u_i, and for even n also sum (-1)^i log u_i (the kernel of lambda).
    x0: u_i = 1 + cos(2 pi i / n) / 2.
    """
    if isinstance(n, bool) or not (isinstance(n, int) and n >= 5):
        raise InputError(f"volterra-lattice: the size must be an integer n >= 5, got {n!r}")
    L = np.zeros((n, n))
    for i in range(n):
        L[i, (i + 1) % n] = 1.0
        L[(i + 1) % n, i] = -1.0
    casimirs = [" + ".join(f"log(x{k})" for k in range(1, n + 1))]
    names = ["log u_1 + ... + log u_n"]
    if n % 2 == 0:
        casimirs.append(" + ".join(f"{(-1) ** k}*log(x{k})" for k in range(1, n + 1)))
        names.append("sum (-1)^i log u_i")
    x0 = 1.0 + 0.5 * np.cos(2 * np.pi * np.arange(1, n + 1) / n)
    return ProblemData("volterra-lattice" if n == 5 else f"volterra-lattice:{n}",
                       None, " + ".join(f"x{k}" for k in range(1, n + 1)),
                       tuple(casimirs), tuple(names), tuple(float(v) for v in x0), 10.0,
                       f"periodic Volterra lattice, log-canonical, n = {n}", LOG_CANONICAL, L)


def lotka_volterra_4d() -> ProblemData:
    """Lotka–Volterra in 4 dimensions (GeometricProblems.jl, LotkaVolterra4d):
    H = sum a_i q_i + b_i log q_i, a = (1, 1, 1, 1), b = (-1, -2, -1, -1), x0 = (2, 1, 1, 1).

    Its vector field q_i' = q_i sum_j lambda_ij (a_j q_j + b_j) with lambda_ij = +1 for j > i and
    -1 for j < i is xdot = pi grad H with pi_ij = lambda_ij q_i q_j: log-canonical in the
    original variables. lambda is non-degenerate (Pfaffian 1): no Casimir.
    """
    L = np.array([[0.0 if i == j else (1.0 if j > i else -1.0) for j in range(4)]
                  for i in range(4)])
    return ProblemData("lotka-volterra-4d", None,
                       "x1 + x2 + x3 + x4 - log(x1) - 2*log(x2) - log(x3) - log(x4)", (), (),
                       (2.0, 1.0, 1.0, 1.0), 10.0,
                       "4-d Lotka-Volterra, log-canonical (GeometricProblems.jl)",
                       LOG_CANONICAL, L)


def lotka_volterra_5d() -> ProblemData:
    """An integrable 5-species Lotka–Volterra system: x_i' = x_i (x_(i+1) - x_(i-1)) (indices mod 5),
    the periodic Kac–van Moerbeke (Volterra) lattice (Volterra, Leçons sur la théorie
    mathématique de la lutte pour la vie, 1931; Kac & van Moerbeke, Adv. Math. 16, 160, 1975),
    written with Volterra's Hamiltonian H = sum (x_i - log x_i) and the log-canonical bracket
    {x_i, x_(i+1)} = x_i x_(i+1) (docs/theory.md §6).

    lambda has rank 4 with kernel (1, 1, 1, 1, 1): C = sum log x_i is the Casimir, and H differs
    from the lattice's sum x_i (``volterra-lattice``) by C, so the flow is the lattice's. On each
    4-dimensional leaf sum x_i and sum (x_i^2/2 + x_i x_(i+1)) are two integrals in involution
    (the lattice's hierarchy, Suris 2003): Liouville integrable. Unlike sum x_i, H is not
    linear: a method that keeps linear invariants (every Runge–Kutta method) still shows its
    drift in H. x0: x_i = 1 + cos(2 pi i / 5)/2, as ``volterra-lattice``.
    """
    n = 5
    L = np.zeros((n, n))
    for i in range(n):
        L[i, (i + 1) % n], L[(i + 1) % n, i] = 1.0, -1.0
    x0 = 1.0 + 0.5 * np.cos(2 * np.pi * np.arange(1, n + 1) / n)
    return ProblemData("lv5-integrable", None,
                       " + ".join(f"x{k} - log(x{k})" for k in range(1, n + 1)),
                       (" + ".join(f"log(x{k})" for k in range(1, n + 1)),),
                       ("log x1 + ... + log x5",), tuple(float(v) for v in x0), 10.0,
                       "5-d Lotka-Volterra, integrable: periodic Kac-van Moerbeke lattice, "
                       "H = sum (x_i - log x_i)", LOG_CANONICAL, L)


def lotka_volterra_5d_nonintegrable() -> ProblemData:
    """A non-integrable 5-species Lotka–Volterra system: lambda_ij = +1 for j > i, -1 for j < i,
    H = sum (x_i - log x_i), i.e. x_i' = x_i (sum_(j>i) (x_j - 1) - sum_(j<i) (x_j - 1)).

    The class x_i' = x_i sum_j lambda_ij (a_j x_j + k_j) (H = sum (a_i x_i + k_i log x_i)) of
    Christodoulidi, Hone & Kouloukas ("A new class of integrable Lotka–Volterra systems",
    J. Comput. Dyn. 6, 223, 2019), with a_i = 1, k_i = -1. The source proves integrability under
    conditions on the parameters and studies the 4-dimensional member with these parameters
    numerically (Poincaré sections, largest Lyapunov exponents) as a case without them; with
    k_i = 0 the class is the superintegrable system of Kouloukas, Quispel & Vanhaecke (J. Phys. A
    49, 225201, 2016). lambda has rank 4 with kernel (1, -1, 1, -1, 1): the Casimir
    log x1 - log x2 + log x3 - log x4 + log x5; H is the only other integral known. Equilibrium
    x = (1, ..., 1); x0 = (3, 1/2, 1, 2, 1/2), H(x0) = 6.59 (a regular-looking orbit there: its
    finite-time Lyapunov exponent falls like 1/t, 4e-4 at t = 2 10^4, as on KAM tori).
    """
    n = 5
    L = np.array([[0.0 if i == j else (1.0 if j > i else -1.0) for j in range(n)] for i in range(n)])
    return ProblemData("lv5-nonintegrable", None,
                       " + ".join(f"x{k} - log(x{k})" for k in range(1, n + 1)),
                       ("log(x1) - log(x2) + log(x3) - log(x4) + log(x5)",),
                       ("sum (-1)^(i+1) log x_i",), (3.0, 0.5, 1.0, 2.0, 0.5), 10.0,
                       "5-d Lotka-Volterra, non-integrable: lambda_ij = sign(j - i), "
                       "H = sum (x_i - log x_i)", LOG_CANONICAL, L)


#: name -> (problem data constructor, whether it takes a size, the default size)
PROBLEMS: dict[str, tuple[Callable, bool]] = {
    "charged-particle": (charged_particle, False),
    "point-vortices": (point_vortices, False),
    "nambu": (nambu, False),
    "heavy-top": (heavy_top, False),
    "toda": (toda, True),
    "volterra-lattice": (volterra_lattice, True),
    "lotka-volterra-4d": (lotka_volterra_4d, False),
    "lv5-integrable": (lotka_volterra_5d, False),
    "lv5-nonintegrable": (lotka_volterra_5d_nonintegrable, False),
}


def problem_data(name: str) -> ProblemData | None:
    """The data of a problem called ``NAME`` or ``NAME:SIZE`` (None if there is none; ``NAME:``, a
    colon without a size, is refused)."""
    base, colon, size = name.partition(":")
    if base not in PROBLEMS:
        return None
    make, sized = PROBLEMS[base]
    if not colon:
        return make()
    if not sized:
        raise InputError(f"{base} has no size parameter (got {name!r})")
    if not (size.isascii() and size.isdigit()):
        raise InputError(f"{name[:40]!r}: the size after ':' must be an integer")
    if len(size) > 6 or int(size) > MAX_DIMENSION:
        raise InputError(f"{name[:40]!r}: the size is at most {MAX_DIMENSION}")
    return make(int(size))


def build(data: ProblemData, realisation: str = "symmetric", general: bool = False
          ) -> PoissonSystem:
    """The system of a problem in its family (or in the general family; pi is read from its
    expressions only there)."""
    H, casimirs = _functions(data)
    symbols = symbols_of(data.dim)
    common = dict(name=data.name, x0=data.x0, t_final=data.t_final, realisation=realisation,
                  description=data.description, hamiltonian_expression=lambda: H)
    hamiltonian = to_program(H, symbols)
    if general or data.family == GENERAL:
        return general_family(PoissonMatrix(_poisson_entries(data)), hamiltonian, casimirs=casimirs,
                              casimir_names=data.casimir_names, where=f"{data.name}: poisson",
                              **common)
    numeric = tuple(numeric_function(c, symbols) for c in casimirs)
    structure = LieAlgebra(data.constants) if data.family == LIE_POISSON else data.constants
    return family_system(data.family, structure, hamiltonian, casimirs=numeric,
                         casimir_names=data.casimir_names, **common)


def as_general(name: str, realisation: str = "symmetric") -> PoissonSystem:
    """A reference problem built in the general family (the spray realisation), e.g. the heavy
    top or the Toda lattice, whose own family has a closed form: for comparisons."""
    data = problem_data(name)
    if data is None:
        raise InputError(f"unknown problem {name!r}; problems: {', '.join(PROBLEMS)}")
    return build(data, realisation, general=True)
