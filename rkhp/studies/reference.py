"""Reference solutions for measured errors, with their own accuracy (docs/theory.md §6).

- ``exact``: the system's closed-form solution (rigid body: Jacobi elliptic functions evaluated
  with mpmath and rounded once), when the start is the system's default ``x0``. Its error is that
  rounding, at most half an ulp a component: it is estimated as ``eps |x(T)|``, and the closed
  form is cross-checked against a tight DOP853 solve: a disagreement larger than that solve's
  estimated error raises NumericalFailure.
- ``dop853``: scipy's DOP853 at rtol 1e-13, atol 1e-15, with its error estimated by a second,
  tighter solve (rtol 2.5e-14, atol 1e-16): the estimate is the distance between the two (at least
  10 eps |x(T)|), and the tighter solve is the reference.
- ``mpmath``: the vector field pi(x) grad H(x) of a system given by expressions (a spec file, a
  built-in system or problem: `PoissonSystem.symbolic`), differentiated by sympy and evaluated in mpmath, integrated by
  mpmath's Taylor-series solver (``mpmath.odefun``) at MP_DIGITS and at MP_DIGITS + MP_CHECK_DIGITS
  digits: the second is the reference, rounded once to float64; its estimate is eps |x(T)| (the
  rounding) plus the distance between the two solves. Chosen (``rkhp converge --reference
  mpmath``), or by a study whose automatic DOP853 reference leaves a method a narrow range of steps
  (`rkhp.studies.converge.choose_study_steps`): where an order above 8 must be seen below DOP853's
  accuracy. The horizon is bounded before the solves: at most MAX_MPMATH_STEPS steps of a DOP853
  probe (rtol 1e-10) to T.

No error at or below ``error_estimate`` (times a safety factor, see :data:`MEASURABLE_FACTOR`) is
reported as a measurement by the studies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError, NumericalFailure

EPS = float(np.finfo(float).eps)
#: steps of one DOP853 reference solve (about a minute), and the steps after which the number
#: needed to reach T is extrapolated and checked against it
MAX_REFERENCE_STEPS = 200_000
PROBE_STEPS = 100
MEASURABLE_FACTOR = 10.0
"""An error counts as a measurement only above MEASURABLE_FACTOR x the reference's error estimate."""

#: digits of the mpmath reference solve, and how many more its check solve carries
MP_DIGITS = 20
MP_CHECK_DIGITS = 6
#: most steps of a DOP853 probe (rtol 1e-10) to T for an mpmath reference (about 10 s at 26
#: digits on the charged particle, T = 10, 2026-11-28)
MAX_MPMATH_STEPS = 2000
PROBE_TOLERANCE = 1e-10
#: the kinds ``reference`` may be asked for ("auto": exact where there is one, else dop853)
KINDS = ("auto", "exact", "dop853", "mpmath")

LOOSE = (1e-13, 1e-15)
TIGHT = (2.5e-14, 1e-16)


@dataclass(frozen=True)
class Reference:
    """A reference state at ``t_final`` and its estimated error (2-norm).

    Attributes:
        kind: "exact" or "dop853".
        state: the reference x(T).
        error_estimate: estimated 2-norm error of ``state``.
        detail: one line saying how it was obtained and checked.
    """

    kind: str
    t_final: float
    state: np.ndarray
    error_estimate: float
    detail: str

    @property
    def floor(self) -> float:
        """Errors at or below this are not reported as measurements."""
        return MEASURABLE_FACTOR * self.error_estimate


def dop853(system, t_final: float, x0, rtol: float, atol: float) -> np.ndarray:
    """x(t_final) by scipy's DOP853 on ``xdot = pi(x) grad H(x)``; NumericalFailure if it fails.

    The vector field is the system's own evaluation (a few thousand calls at most, no compilation:
    the compiled one of :mod:`rkhp.integrators.classical` serves the timed peers of ``bench``).
    The solver is stepped here (as solve_ivp does) so that a horizon too long for a reference is
    refused early: after PROBE_STEPS steps the number of steps to T is extrapolated, and above
    MAX_REFERENCE_STEPS the solve stops with an InputError (docs/input.md)."""
    from scipy.integrate import DOP853

    f = system.vector_field
    t_final = float(t_final)
    solver = DOP853(lambda t, x: f(x), 0.0, np.asarray(x0, dtype=float), t_final, rtol=rtol, atol=atol)
    steps, message = 0, None
    while solver.status == "running":
        message = solver.step()
        steps += 1
        if solver.status == "running" and (steps == PROBE_STEPS or steps > MAX_REFERENCE_STEPS):
            needed = steps * t_final / solver.t if solver.t > 0 else math.inf
            if needed > MAX_REFERENCE_STEPS:
                many = f"about {needed:.3g}" if math.isfinite(needed) else "unboundedly many"
                raise InputError(f"T = {t_final:g} is too long for a reference solution of {system.name}: "
                                 f"DOP853 would take {many} steps (at most {MAX_REFERENCE_STEPS}); "
                                 "give a smaller --t-final")
    if solver.status != "finished" or not np.all(np.isfinite(solver.y)):
        raise NumericalFailure(f"reference solve (DOP853, rtol {rtol:g}) failed on {system.name}: "
                               f"{message or 'non-finite state'}")
    return solver.y


def dop853_reference(system, t_final: float, x0=None) -> Reference:
    """The tighter of two DOP853 solves, its error estimated by their distance."""
    x0 = np.asarray(system.x0 if x0 is None else x0, dtype=float)
    loose = dop853(system, t_final, x0, *LOOSE)
    tight = dop853(system, t_final, x0, *TIGHT)
    estimate = max(float(np.linalg.norm(loose - tight)), 10 * EPS * float(np.linalg.norm(tight)))
    detail = (f"scipy DOP853 at rtol {TIGHT[0]:g}, atol {TIGHT[1]:g}; error estimated against a second "
              f"solve at rtol {LOOSE[0]:g}, atol {LOOSE[1]:g}")
    return Reference("dop853", float(t_final), tight, estimate, detail)


def exact_reference(system, t_final: float) -> Reference:
    """The closed-form solution at ``t_final``, cross-checked against DOP853."""
    state = np.asarray(system.exact_solution(float(t_final)), dtype=float)
    estimate = EPS * float(np.linalg.norm(state))
    check = dop853_reference(system, t_final)
    gap = float(np.linalg.norm(check.state - state))
    if gap > 10 * check.error_estimate + estimate:
        raise NumericalFailure(
            f"the exact solution of {system.name} at t = {t_final:g} disagrees with DOP853 by {gap:.3g} "
            f"(DOP853 error estimate {check.error_estimate:.3g})")
    detail = (f"closed-form solution, rounded once; round-off estimate eps |x(T)|; agrees with DOP853 "
              f"to {gap:.2g} (DOP853 error estimate {check.error_estimate:.2g})")
    return Reference("exact", float(t_final), state, estimate, detail)


def _probe_steps(system, t_final: float, x0) -> int:
    """Steps of DOP853 at rtol PROBE_TOLERANCE to ``t_final``; InputError past MAX_MPMATH_STEPS."""
    from scipy.integrate import DOP853

    f = system.vector_field
    solver = DOP853(lambda t, x: f(x), 0.0, x0, float(t_final), rtol=PROBE_TOLERANCE, atol=PROBE_TOLERANCE)
    steps = 0
    while solver.status == "running":
        solver.step()
        steps += 1
        if steps > MAX_MPMATH_STEPS:
            raise InputError(f"T = {t_final:g} is too long for an mpmath reference of {system.name}: more than "
                             f"{MAX_MPMATH_STEPS} steps of a DOP853 probe; give a smaller --t-final")
    if solver.status != "finished":
        raise NumericalFailure(f"reference probe (DOP853) failed on {system.name}")
    return steps


def symbolic_field(system):
    """(symbols, pi(x) grad H(x) as sympy expressions) of a system given by expressions
    (`PoissonSystem.symbolic`: spec files, the built-in systems and problems), checked against the
    system's own vector field at its x0; InputError for a system built from programs alone."""
    symbolic = system.symbolic()
    if symbolic is None:
        raise InputError(f"an mpmath reference needs the expressions of the system: {system.name} was "
                         "built from programs alone (give it by a spec file or rkhp.system)")
    symbols, field = symbolic.symbols, symbolic.vector_field()
    at_start = np.array([float(e.subs(dict(zip(symbols, system.x0, strict=True)))) for e in field])
    if not np.allclose(at_start, system.vector_field(np.asarray(system.x0, dtype=float)), rtol=1e-12, atol=1e-14):
        raise InputError(f"{system.name} is not the problem of that name: no mpmath reference for it")
    return symbols, field


def mpmath_reference(system, t_final: float, x0=None) -> Reference:
    """x(T) by mpmath's Taylor-series solver at MP_DIGITS + MP_CHECK_DIGITS digits, checked against
    a solve at MP_DIGITS (module docstring)."""
    import mpmath
    import sympy

    x0 = np.asarray(system.x0 if x0 is None else x0, dtype=float)
    _probe_steps(system, t_final, x0)
    symbols, field = symbolic_field(system)
    f = sympy.lambdify(symbols, field, modules="mpmath")
    solves = []
    for digits in (MP_DIGITS, MP_DIGITS + MP_CHECK_DIGITS):
        with mpmath.workdps(digits):
            solution = mpmath.odefun(lambda t, y: f(*y), 0, [mpmath.mpf(float(v)) for v in x0])
            solves.append([+v for v in solution(mpmath.mpf(float(t_final)))])
    with mpmath.workdps(MP_DIGITS + MP_CHECK_DIGITS):
        gap = float(mpmath.sqrt(mpmath.fsum((a - b) ** 2 for a, b in zip(*solves, strict=True))))
    state = np.array([float(v) for v in solves[1]])
    if not np.all(np.isfinite(state)):
        raise NumericalFailure(f"reference solve (mpmath) on {system.name} is not finite")
    estimate = EPS * float(np.linalg.norm(state)) + gap
    detail = (f"mpmath Taylor series (odefun) at {MP_DIGITS + MP_CHECK_DIGITS} digits, rounded once; error "
              f"estimated as eps |x(T)| plus its distance to a solve at {MP_DIGITS} digits ({gap:.1e})")
    return Reference("mpmath", float(t_final), state, estimate, detail)


def reference(system, t_final: float, x0=None, kind: str = "auto") -> Reference:
    """The reference of ``kind`` (KINDS; "auto": the closed form where ``system`` has one and
    starts from its default ``x0``, else DOP853) for ``system`` from ``x0`` at ``t_final``."""
    if kind not in KINDS:
        raise InputError(f"unknown reference {kind!r}; choose one of {', '.join(KINDS)}")
    default_start = x0 is None or np.array_equal(np.asarray(x0, dtype=float), np.asarray(system.x0, dtype=float))
    exact = getattr(system, "exact_solution", None) is not None and default_start
    if kind == "mpmath":
        return mpmath_reference(system, t_final, x0)
    if kind == "exact" and not exact:
        raise InputError(f"{system.name} has no closed-form solution from this start; choose --reference "
                         "dop853 or mpmath")
    if exact and kind != "dop853":
        return exact_reference(system, t_final)
    return dop853_reference(system, t_final, x0)
