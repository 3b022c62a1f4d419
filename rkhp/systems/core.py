"""The Poisson system value and its realisations (docs/theory.md §4, paper §2).

A system is given by its Poisson matrix pi(x), its Hamiltonian H and a *base* birealisation
(alpha, beta) that is symmetric, beta(x, p) = alpha(x, -p). A realisation composes the base with a
symplectomorphism of T*M fixing the zero section, (x, p) -> (x + s(p), p):

- ``symmetric``: s = 0 (degenerate: d_p alpha(x, 0) = -pi(x)/2 is antisymmetric);
- ``shifted``: s(p) = Q p with the constant symmetric matrix Q = SHIFT_Q (diagonal 1/2,
  off-diagonal 1/4; docs/theory.md §4), which breaks the degeneracy: d_p alpha(x, 0) = -pi(x)/2 + Q;
- further kinds join with :func:`register_realisation` (e.g. ``quartic``,
  s(p) = grad K(p) with K(p) even in p, which stays degenerate).

The symmetric bases come from the registry of Poisson families (`rkhp.systems.families`). H,
alpha and beta are recorded as tapes (`rkhp.taylor.tape`) that the compiled interpreter
(`rkhp.taylor.interpreter`) evaluates in Taylor arithmetic; the numpy-level callables below
evaluate the same tapes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from ..base.bounds import real_vector
from ..base.errors import InputError
from ..taylor import tape as tp
from .spray import MAX_TRUNCATION, truncated_order, truncated_realisation

DOMAINS = {"R^n": 0, "positive orthant": 1}


def shift_matrix(n: int) -> np.ndarray:
    """SHIFT_Q of the ``shifted`` realisation: 1/2 on the diagonal, 1/4 off it (symmetric)."""
    return 0.25 * np.ones((n, n)) + 0.25 * np.eye(n)


def _no_shift(p):
    return None


def _q_shift(p):
    Q = shift_matrix(len(p))
    return [sum(Q[i, j] * p[j] for j in range(len(p))) for i in range(len(p))]


@dataclass(frozen=True)
class Realisation:
    """How the base (symmetric) birealisation is composed: x -> x + shift(p) (shift of tape Vars,
    None for no shift), and whether the result is degenerate (d_p alpha(x,0) antisymmetric).
    With `truncation` K, the base itself is replaced by the spray realisation of pi truncated at
    degree K in p (`rkhp.systems.spray`, docs/theory.md §9)."""

    name: str
    shift: Callable
    degenerate: bool
    description: str
    symmetric: bool = False
    truncation: int | None = None


REALISATIONS: dict[str, Realisation] = {}


def register_realisation(name: str, shift: Callable, degenerate: bool, description: str,
                         symmetric: bool = False) -> None:
    """Add a realisation kind (shift: list of n tape Vars p -> list of n shifts, or None;
    symmetric: beta(x, p) = alpha(x, -p), i.e. the shift is even in p)."""
    REALISATIONS[name] = Realisation(name, shift, degenerate, description, symmetric)


register_realisation("symmetric", _no_shift, True, "beta(x, p) = alpha(x, -p) (docs/theory.md §4)",
                     symmetric=True)
register_realisation("shifted", _q_shift, False,
                     "alpha(x + Q p, p), Q = 1/2 on the diagonal and 1/4 off it (docs/theory.md §4)")


TRUNCATED = "truncated:"


def truncated(name: str) -> Realisation:
    """The kind ``truncated:K``: the spray realisation's series to degree K in p (symmetric,
    degenerate; docs/theory.md §9); InputError unless 1 <= K <= MAX_TRUNCATION."""
    text = name[len(TRUNCATED):]
    if not (text.isascii() and text.isdigit() and len(text) <= 3 and 1 <= int(text) <= MAX_TRUNCATION):
        raise InputError(f"realisation {name[:40]!r}: K in truncated:K must be an integer from 1 to "
                         f"{MAX_TRUNCATION}")
    K = int(text)
    return Realisation(f"{TRUNCATED}{K}", _no_shift, True,
                       f"the spray realisation truncated at degree {K} in p (docs/theory.md §9)",
                       symmetric=True, truncation=K)


def realisation(name: str) -> Realisation:
    """The realisation kind called `name` (InputError listing the known kinds otherwise)."""
    if isinstance(name, str) and name.startswith(TRUNCATED):
        return truncated(name)
    if name not in REALISATIONS:
        raise InputError(f"unknown realisation {name!r}; choose one of {', '.join(REALISATIONS)}, "
                         f"{TRUNCATED}K")
    return REALISATIONS[name]


class SymbolicSystem(NamedTuple):
    """A system as sympy expressions in the real symbols x1..xn: pi(x) by rows and H(x)
    (docs/theory.md §4); what a reference computed from the expressions integrates
    (`rkhp.studies.reference`)."""

    symbols: tuple
    poisson: tuple
    hamiltonian: object

    def vector_field(self) -> list:
        """xdot = pi(x) grad H(x), entry by entry."""
        import sympy

        grad = [sympy.diff(self.hamiltonian, x) for x in self.symbols]
        return [sum((row[j] * grad[j] for j in range(len(grad))), sympy.Integer(0)) for row in self.poisson]


@dataclass(frozen=True, eq=False)
class PoissonSystem:
    """A Poisson system xdot = pi(x) grad H(x) with a birealisation (alpha, beta).

    Numpy-level callables take float arrays of shape (n,): `poisson(x) -> (n, n)`,
    `hamiltonian(x) -> float`, `grad_hamiltonian(x) -> (n,)`, `casimirs` (x -> float each),
    `alpha(x, p)`, `beta(x, p)`, `in_domain(x) -> bool`, `vector_field(x) -> (n,)`.
    `exact_solution(t)` (or None) is the exact solution from the system's own `x0`.
    `invariants` (x -> float each, named by `invariant_names`): first integrals the user declared
    (a spec file's ``invariants``), reported like the energy (docs/spec-files.md).
    The engine uses the tapes: `h_tape` (H), `f_tape` (H o alpha), `alpha_tape`, `beta_tape`,
    all over the 2n inputs (x, p), and `domain_code` (0: R^n, 1: positive orthant).
    `poisson_degree`: the degree of pi as a polynomial in x (0 constant, 1 linear, ...; None when
    pi is not a polynomial): it decides which terms of the spray series vanish, hence the order
    a ``truncated:K`` realisation allows (`realisation_order`).
    `structure`: the data of pi in its family (`rkhp.systems.families`: structure constants,
    lambda, a matrix of expressions...), from which the family's ``symbolic`` gives pi as sympy
    expressions (`rkhp.systems.field_code`).
    """

    name: str
    dim: int
    family: str
    realisation: str
    degenerate: bool
    poisson: Callable
    x0: np.ndarray
    t_final: float
    h_tape: tp.Tape
    f_tape: tp.Tape
    alpha_tape: tp.Tape
    beta_tape: tp.Tape
    domain: str = "R^n"
    casimirs: tuple = ()
    casimir_names: tuple = ()
    exact_solution: Callable | None = None
    description: str = ""
    extra: dict = field(default_factory=dict)
    poisson_degree: int | None = None
    structure: object = None
    invariants: tuple = ()
    invariant_names: tuple = ()

    @property
    def realisation_order(self) -> int | None:
        """The largest order an RKHP method can reach with this realisation (None: no bound;
        ``truncated:K``: docs/theory.md §9)."""
        K = realisation(self.realisation).truncation
        if K is None:
            return None
        return truncated_order(K, self.poisson_degree)

    @property
    def symmetric(self) -> bool:
        """beta(x, p) = alpha(x, -p) (docs/theory.md §8): the symmetric order conditions apply."""
        return realisation(self.realisation).symmetric

    @property
    def domain_code(self) -> int:
        return DOMAINS[self.domain]

    def _xp(self, x, p=None) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        p = np.zeros(self.dim) if p is None else np.asarray(p, dtype=np.float64).reshape(-1)
        if x.shape != (self.dim,) or p.shape != (self.dim,):
            raise InputError(f"{self.name}: expected vectors of size {self.dim}")
        return np.concatenate([x, p])

    def hamiltonian(self, x) -> float:
        from ..taylor.interpreter import evaluate

        return float(evaluate(self.h_tape, self._xp(x))[0])

    def grad_hamiltonian(self, x) -> np.ndarray:
        from ..taylor.interpreter import evaluate

        _, jac = evaluate(self.h_tape, self._xp(x), degree=1, n_vars=2 * self.dim)
        return jac[0, : self.dim]

    def vector_field(self, x) -> np.ndarray:
        """pi(x) grad H(x)."""
        return self.poisson(np.asarray(x, dtype=np.float64)) @ self.grad_hamiltonian(x)

    def alpha(self, x, p) -> np.ndarray:
        from ..taylor.interpreter import evaluate

        return evaluate(self.alpha_tape, self._xp(x, p))

    def beta(self, x, p) -> np.ndarray:
        from ..taylor.interpreter import evaluate

        return evaluate(self.beta_tape, self._xp(x, p))

    def in_domain(self, x) -> bool:
        x = np.asarray(x, dtype=np.float64)
        return x.shape == (self.dim,) and self._admits(x)

    def _admits(self, x: np.ndarray) -> bool:
        """Whether a float64 vector of the system's dimension is finite and in its domain."""
        if not np.isfinite(x).all():
            return False
        return self.domain != "positive orthant" or bool(x.min() > 0.0)

    def _checked_x0(self, x0) -> np.ndarray:
        """``x0`` as a new float64 vector if it is one of the system's states (real numbers, as
        many as the dimension, finite, in the domain); InputError naming what is wrong otherwise."""
        if isinstance(x0, np.ndarray) and x0.ndim == 1 and x0.dtype.kind in "fiu":
            x0 = np.array(x0, dtype=np.float64)  # an array of reals: checked as a whole
            if not np.isfinite(x0).all():
                x0 = np.array(real_vector(x0, "x0"), dtype=np.float64)  # the component to name
        else:
            x0 = np.array(real_vector(x0, "x0"), dtype=np.float64)
        if x0.shape != (self.dim,):
            raise InputError(f"x0 has {x0.size} components; {self.name} has dimension {self.dim}")
        if not self._admits(x0):
            raise InputError(f"x0 = {x0.tolist()} is outside the domain ({self.domain}) of "
                             f"{self.name}")
        return x0

    def symbolic(self) -> SymbolicSystem | None:
        """The system as expressions where it was given by them (spec files, the built-in systems,
        the reference problems: `rkhp.systems.families.family_system`'s ``hamiltonian_expression``);
        None for one built from programs alone."""
        make = self.extra.get("symbolic")
        return None if make is None else make()

    def casimir_values(self, x) -> np.ndarray:
        return np.array([c(np.asarray(x, dtype=np.float64)) for c in self.casimirs])

    def invariant_values(self, x) -> np.ndarray:
        """The declared invariants at x (an empty array without any)."""
        return np.array([f(np.asarray(x, dtype=np.float64)) for f in self.invariants])

    def start(self, x0=None) -> np.ndarray:
        """The state a run starts from, as a new float64 vector: ``x0`` checked as by
        :meth:`with_x0` (size, finite, domain), or the system's own when None."""
        return np.array(self.x0, dtype=np.float64) if x0 is None else self._checked_x0(x0)

    def with_x0(self, x0) -> PoissonSystem:
        """The same system started elsewhere (checked: size and domain; no exact solution)."""
        x0 = self._checked_x0(x0)
        same = np.array_equal(x0, self.x0)
        return replace(self, x0=x0, exact_solution=self.exact_solution if same else None)


def build_system(*, name: str, family: str, dim: int, poisson: Callable, hamiltonian: Callable,
                 base_alpha: Callable, base_beta: Callable, x0, t_final: float,
                 poisson_program: Callable, poisson_degree: int | None,
                 realisation_name: str = "symmetric", domain: str = "R^n",
                 casimirs: tuple = (), casimir_names: tuple = (),
                 exact_solution: Callable | None = None, description: str = "",
                 structure=None) -> PoissonSystem:
    """Record the tapes of a system from programs over tape Vars.

    hamiltonian(x) -> Var; base_alpha(x, p), base_beta(x, p) -> lists of n Vars: the symmetric
    base birealisation; the realisation named `realisation_name` is composed on top.
    poisson_program(y) -> n x n entries (numbers or functions of y with + - * / ** and the tape
    functions): pi at the tape level, for the ``truncated:K`` realisations; poisson_degree: its
    degree as a polynomial (None if it is not one); structure: the family's data of pi, kept on
    the system.
    """
    kind = realisation(realisation_name)
    if kind.truncation is not None:
        base_alpha, base_beta = truncated_realisation(poisson_program, kind.truncation)

    def shifted(x, p):
        s = kind.shift(p)
        return x if s is None else [xi + si for xi, si in zip(x, s, strict=True)]

    def alpha(x, p):
        return base_alpha(shifted(x, p), p)

    def beta(x, p):
        return base_beta(shifted(x, p), p)

    x0 = np.asarray(x0, dtype=np.float64)
    h_tape, f_tape, alpha_tape, beta_tape = tp.common_class(
        (tp.record_tape(dim, lambda x, p: [hamiltonian(x)]),
         tp.record_tape(dim, lambda x, p: [hamiltonian(alpha(x, p))]),
         tp.record_tape(dim, alpha), tp.record_tape(dim, beta)))
    return PoissonSystem(
        name=name, dim=dim, family=family, realisation=kind.name, degenerate=kind.degenerate,
        poisson=poisson, x0=x0, t_final=float(t_final),
        h_tape=h_tape, f_tape=f_tape, alpha_tape=alpha_tape, beta_tape=beta_tape,
        domain=domain, casimirs=tuple(casimirs), casimir_names=tuple(casimir_names),
        exact_solution=exact_solution, description=description, poisson_degree=poisson_degree,
        structure=structure,
    )
