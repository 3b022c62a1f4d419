"""What `rkhp stability` reports for a tableau or a composition, and theta(z) in float64 for plots
(docs/stability.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mpmath

from ...base.errors import InputError
from ..tableau import Tableau
from .explicit import explicit_angles, m_polynomial, poly_text, wrap_limit_explicit, wrap_limit_numeric
from .field import Number, exact_text, tableau_field
from .implicit import branch_point, check_implicit_stages, implicit_branch, mp_tableau
from .phase import Phase, check_series_order, composition_phase, phase, phase_of
from .shifted import (
    shifted_branch,
    shifted_stage_equations,
    shifted_trace,
    shifted_trace_series,
    stability_interval,
    step_matrix_shifted,
    theta_of_trace,
    trace_phase,
)

REALISATIONS = ("symmetric", "shifted")


@dataclass(frozen=True)
class Stability:
    """What `rkhp stability` reports for one method (docs/stability.md, docs/json.md).

    kind: ``explicit``, ``implicit`` or ``composition``; m: the exact polynomial m(z) as text
    (explicit, symmetric realisation, at most MAX_POLYNOMIAL_STAGES stages; else None);
    stage_equations: implicit tableaux; trace: tr R(z) (shifted realisation).
    """

    name: str
    kind: str
    realisation: str
    m: str | None
    m_degree: int | None
    stage_equations: tuple[str, ...] | None
    phase: Phase
    wrap_limit: Number | None
    existence_limit: Number | None
    trace: str | None
    stability_interval: Number | None


def analyse(tableau: Tableau, order: int = 9, realisation: str = "symmetric") -> Stability:
    """The linear stability and phase of an RKHP tableau (see the module)."""
    check_series_order(order)
    if realisation not in REALISATIONS:
        raise InputError(f"unknown realisation {realisation!r} for the linear analysis; choose one of "
                         f"{', '.join(REALISATIONS)}")
    check_implicit_stages(tableau, realisation)
    if realisation == "shifted" and tableau.is_explicit:
        trace = shifted_trace(tableau)
        F = tableau_field(tableau)
        return Stability(tableau.name, "explicit", realisation, None, None, None, trace_phase(F, trace, order),
                         None, None, exact_text(trace) if tableau.is_exact else None,
                         stability_interval(trace, F.K))
    if realisation == "shifted":
        F = tableau_field(tableau)
        ph = phase_of(F, lambda n: theta_of_trace(F.K, shifted_trace_series(F, n + 2), n), order)
        branch = shifted_branch(tableau)
        return Stability(tableau.name, "implicit", realisation, None, None, shifted_stage_equations(tableau), ph,
                         None, branch.existence_limit, None, branch.stability_interval)
    ph = phase(tableau, order)
    if tableau.is_explicit:
        m = m_polynomial(tableau)
        wrap = wrap_limit_explicit(m) if m is not None else wrap_limit_numeric(tableau)
        return Stability(tableau.name, "explicit", realisation, None if m is None else poly_text(m),
                         None if m is None else m.degree(), None, ph, wrap, None, None, None)
    branch = implicit_branch(tableau)
    return Stability(tableau.name, "implicit", realisation, None, None, branch.equations, ph,
                     branch.wrap_limit, branch.existence_limit, None, None)


def analyse_composition(name: str, tableau: Tableau, gammas, order: int = 9,
                        digits: int | None = None) -> Stability:
    """The phase of a composition of the RKHP step of `tableau` with substeps gamma_i h
    (`composition_phase`; symmetric realisation). Its substeps turn back and forth, so theta is not
    monotone and no wrap limit is given. Coefficients known to `digits` digits (decimals read
    exactly) leave residues of that size: those coefficients of theta - z count as zero."""
    ph = composition_phase(tableau, gammas, order)
    return Stability(name, "composition", "symmetric", None, None, None,
                     ph if digits is None else _within_digits(ph, digits), None, None, None, None)


def _within_digits(ph: Phase, digits: int) -> Phase:
    """`ph` with the coefficients below 10^-(digits - 5) as zeros and the others by their values
    (the exact decimals' long rationals say no more than their digits)."""
    tol = 10.0 ** -(digits - 5)
    coefficients = tuple((k, Number(None, c.value) if abs(c.value) > tol else Number("0", 0.0))
                         for k, c in ph.coefficients)
    nonzero = [(k, c) for k, c in coefficients if c.value != 0.0]
    if not nonzero:
        return Phase(ph.order, coefficients, None, None, ph.searched)
    k, c = nonzero[0]
    return Phase(ph.order, coefficients, k - 1, c, ph.searched)


def rotation_angle(tableau: Tableau, z: float, realisation: str = "symmetric") -> float | None:
    """theta(z) in float64: 2 arctan(m(z)/2) (symmetric realisation; None where an implicit
    tableau's branch has no solution at z), arccos(tr R/2) (shifted; None where |tr R| > 2)."""
    return rotation_angles(tableau, [z], realisation)[0]


def rotation_angles(tableau: Tableau, zs, realisation: str = "symmetric") -> list[float | None]:
    """`rotation_angle` at each z of the increasing ``zs``; an implicit tableau's branch (symmetric
    realisation) is continued from one z to the next, and once it has ended (past its fold) every
    later z has no solution."""
    check_implicit_stages(tableau, realisation)
    if realisation == "shifted":
        angles = []
        for z in zs:
            R = step_matrix_shifted(tableau, z)
            tr = None if R is None else float(R.trace())
            angles.append(math.acos(tr / 2) if tr is not None and abs(tr) <= 2 else None)
        return angles
    A, b = tableau.A_float, tableau.b_float
    s = tableau.stages

    def angle(ms, z):
        return 2.0 * math.atan(z * sum(b[i] * (1 + ms[i] ** 2 / 4) for i in range(s)) / 2)

    if tableau.is_explicit:
        return explicit_angles(A, b, zs)
    angles, start = [], None
    with mpmath.workdps(25):
        A_mp = mp_tableau(tableau)[0]
        for z in zs:
            target = mpmath.mpf(z)
            point = None if start is False else branch_point(A_mp, target, start)
            start = False if point is None else (point, target)
            angles.append(None if point is None else angle([float(x) for x in point], z))
    return angles

