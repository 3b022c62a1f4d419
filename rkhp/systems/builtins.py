"""Built-in systems (docs/theory.md §6): the rigid body, Lotka–Volterra (3 species) and the
pendulum, each a structure of a registered family (`rkhp.systems.families`)."""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..taylor import tape as tp
from .core import PoissonSystem
from .families import CONSTANT, LIE_POISSON, LOG_CANONICAL, SO3, LieAlgebra, family_system
from .problems import PROBLEMS, build, problem_data
from .spec import spec_system, spec_text
from .structure import symbols_of

RIGID_BODY_I = (2.0, 1.0, 2.0 / 3.0)
RIGID_BODY_X0 = (math.cos(1.1), 0.0, math.sin(1.1))
LV_LAMBDA = ((0.0, 1.0, 2.0), (-1.0, 0.0, 1.0), (-2.0, -1.0, 0.0))
LV_X0 = (0.5, 1.0, 2.0)
PENDULUM_X0 = (1.5, 0.0)


EXACT_DIGITS = 30
"""Digits at which the rigid body's closed form is evaluated (mpmath), before one rounding to float64."""


def rigid_body_exact(inertia, x0) -> Callable | None:
    """Exact solution of xdot = x cross grad H, H = sum x_i^2 / (2 I_i), by Jacobi elliptic
    functions, or None.

    Valid for I1 > I2 > I3 (a_i = 1/I_i increasing), x0 = (A, 0, C) with C != 0 and energy
    above the middle axis (sum a_i x_i^2 > a2 |x|^2): then x1 = A cn(tau), x2 = B sn(tau),
    x3 = C dn(tau), tau = lam t, lam = |C| sqrt((a3 - a2)(a3 - a1)) sign(C),
    B = (a1 - a3) A C / lam, k^2 = (a2 - a1) A^2 / ((a3 - a2) C^2)  (from Euler's equations
    x1' = (a3-a2) x2 x3, x2' = (a1-a3) x3 x1, x3' = (a2-a1) x1 x2).

    The solution is that of the Hamiltonian the integrators evaluate (a_i = 2 fl(0.5 / I_i), the
    float64 coefficients of H, exactly), evaluated with mpmath at EXACT_DIGITS digits for the given
    float64 times and rounded once: each component is within half an ulp of the exact value.
    """
    import mpmath

    with mpmath.workdps(EXACT_DIGITS):
        a1, a2, a3 = (2 * mpmath.mpf(0.5 / float(v)) for v in inertia)
        A, x2, C = (mpmath.mpf(float(v)) for v in x0)
        if not (a1 < a2 < a3) or x2 != 0 or C == 0:
            return None
        if not a1 * A * A + a3 * C * C > a2 * (A * A + C * C):
            return None
        lam = C * mpmath.sqrt((a3 - a2) * (a3 - a1))
        B = (a1 - a3) * A * C / lam
        m = (a2 - a1) * A * A / ((a3 - a2) * C * C)

    def state_at(t: float) -> list[float]:
        with mpmath.workdps(EXACT_DIGITS):
            tau = lam * mpmath.mpf(t)
            return [float(A * mpmath.ellipfun("cn", tau, m=m)), float(B * mpmath.ellipfun("sn", tau, m=m)),
                    float(C * mpmath.ellipfun("dn", tau, m=m))]

    def solution(t):
        times = np.asarray(t, dtype=np.float64)
        values = np.array([state_at(float(v)) for v in times.ravel()])
        return values.reshape(*times.shape, 3)

    return solution


def _expression(formula, n: int):
    """A Hamiltonian as a sympy expression, ``formula(x, sympy)`` in the real symbols x1..xn (the
    coefficients the tapes use, exactly: a float64 coefficient as its binary rational)."""
    import sympy

    return formula(symbols_of(n), sympy)


def rigid_body(realisation: str = "symmetric") -> PoissonSystem:
    """Free rigid body on so(3)* (pi(x) v = x cross v, closed-form realisation),
    H = sum x_i^2 / (2 I_i), I = (2, 1, 2/3) (HLW, docs/theory.md §6)."""
    inertia = RIGID_BODY_I
    return family_system(
        LIE_POISSON, LieAlgebra(SO3, closed_form=True),
        lambda x: sum((0.5 / inertia[i]) * (x[i] * x[i]) for i in range(3)),
        name="rigid-body", x0=RIGID_BODY_X0, t_final=10.0, realisation=realisation,
        casimirs=(lambda x: 0.5 * float(np.dot(x, x)),), casimir_names=("|x|^2/2",),
        exact_solution=rigid_body_exact(inertia, RIGID_BODY_X0),
        description="free rigid body, so(3)*, I = (2, 1, 2/3)",
        hamiltonian_expression=lambda: _expression(
            lambda x, sympy: sum(sympy.Rational(0.5 / inertia[i]) * x[i] ** 2 for i in range(3)), 3))


def lotka_volterra(realisation: str = "symmetric") -> PoissonSystem:
    """3-species Lotka–Volterra, log-canonical, H = sum (x_i - log x_i) (docs/theory.md §6)."""
    return family_system(
        LOG_CANONICAL, np.array(LV_LAMBDA), lambda x: sum(x[i] - tp.log(x[i]) for i in range(3)),
        name="lotka-volterra", x0=LV_X0, t_final=10.0, realisation=realisation,
        casimirs=(lambda x: float(np.log(x[0]) - 2.0 * np.log(x[1]) + np.log(x[2])),),
        casimir_names=("log x1 - 2 log x2 + log x3",),
        description="3-species Lotka-Volterra, log-canonical, "
                    "lambda = [[0,1,2],[-1,0,1],[-2,-1,0]]",
        hamiltonian_expression=lambda: _expression(lambda x, sympy: sum(x[i] - sympy.log(x[i]) for i in range(3)), 3))


def pendulum(realisation: str = "symmetric") -> PoissonSystem:
    """Mathematical pendulum, canonical pi = [[0, 1], [-1, 0]], H = p^2/2 - cos q, x = (q, p)."""
    return family_system(CONSTANT, np.array(((0.0, 1.0), (-1.0, 0.0))),
                         lambda x: 0.5 * (x[1] * x[1]) - tp.cos(x[0]),
                         name="pendulum", x0=PENDULUM_X0, t_final=10.0, realisation=realisation,
                         description="pendulum, canonical (constant pi), H = p^2/2 - cos q",
                         hamiltonian_expression=lambda: _expression(
                             lambda x, sympy: x[1] ** 2 / 2 - sympy.cos(x[0]), 2))


BUILTINS: dict[str, Callable[[str], PoissonSystem]] = {
    "rigid-body": rigid_body,
    "lotka-volterra": lotka_volterra,
    "pendulum": pendulum,
}


def builtin_systems() -> tuple[str, ...]:
    """Names of the built-in systems: docs/theory.md §6's three, then the reference problems of
    `rkhp.systems.problems` (``toda`` and ``volterra-lattice`` also as ``NAME:SIZE``)."""
    return tuple(BUILTINS) + tuple(PROBLEMS)


SYSTEMS_KEPT = 32
"""How many systems built by name (and how many built from spec files) a process keeps."""


def get_system(name_or_path, realisation: str = "symmetric") -> PoissonSystem:
    """A built-in system by name (``toda:12``: with its size), or a system from a spec file
    (.toml or .json).

    A system is built once: the same name and realisation, or a spec file of the same path,
    content and realisation, give back the same object (the SYSTEMS_KEPT most recently used of
    each kind are kept); a spec file is read again on every call, so an edited file is built
    again."""
    key = str(name_or_path)
    if key in BUILTINS or key.partition(":")[0] in PROBLEMS:
        return _built_in(key, realisation)
    path = Path(key)
    if path.suffix.lower() in (".toml", ".json"):
        return _from_spec(key, spec_text(path), realisation)
    names = builtin_systems()
    close = difflib.get_close_matches(key, names, n=2)
    hint = f"; did you mean {' or '.join(close)}?" if close else ""
    raise InputError(f"unknown system {key!r} (built-ins: {', '.join(names)}, or a .toml/.json "
                     f"spec file){hint}")


@lru_cache(maxsize=SYSTEMS_KEPT)
def _built_in(key: str, realisation: str) -> PoissonSystem:
    """The built-in system `key` (a name of BUILTINS or a problem's ``NAME[:SIZE]``)."""
    if key in BUILTINS:
        return BUILTINS[key](realisation)
    return build(problem_data(key), realisation)


@lru_cache(maxsize=SYSTEMS_KEPT)
def _from_spec(path: str, text: str, realisation: str) -> PoissonSystem:
    """The system of the spec file at `path` whose text is `text` (the cache's key holds the
    text itself: its hash finds the entry, an equal text confirms it)."""
    return spec_system(text, path, realisation)
