"""Methods a study can run, all in one harness: RKHP tableaux and the classical peers.

A method is named by a string:

- ``NAME`` or ``FILE``: a tableau (built-in name, alias, or tableau file) used as an RKHP method
  (paper §5.2, NOTES §5), e.g. ``rk4`` is RK4 used as an RKHP tableau;
- ``classical:NAME`` or ``classical:FILE``: that tableau as a classical explicit Runge–Kutta
  method on ``xdot = pi(x) grad H(x)``;
- ``implicit-midpoint``: the implicit midpoint rule (Newton per step).

The expected order comes from the verify engine: for RKHP, the symmetric order (the reduced
conditions of NOTES §8) on a symmetric realisation, the degenerate order (over T_0) on a degenerate
one and the general order (over T) otherwise (paper, Theorems 4.4 and 5.1); for a classical method,
its order over T (the classical order conditions); 2 for the midpoint rule.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError

DEFAULT_METHODS = ("euler", "paper-two-stage", "paper-three-stage", "rk4")
CLASSICAL_PREFIX = "classical:"
MIDPOINT = "implicit-midpoint"


@dataclass(frozen=True)
class Method:
    """A named method with its tableau (None for the implicit midpoint rule).

    Attributes:
        name: the name as given by the user.
        kind: "rkhp", "classical" or "implicit-midpoint".
        tableau: a :class:`rkhp.tableau.Tableau` or None.
    """

    name: str
    kind: str
    tableau: object = None

    def integrate(self, system, h: float, n_steps: int, x0=None):
        """Run the method; returns a :class:`~rkhp.integrators.trajectory.Trajectory`."""
        if self.kind == "rkhp":
            from ..integrators import integrate

            return integrate(system, self.tableau, h, n_steps, x0)
        if self.kind == "classical":
            from ..integrators.classical import integrate_classical

            return integrate_classical(system, self.tableau, h, n_steps, x0)
        from ..integrators.classical import integrate_midpoint

        return integrate_midpoint(system, h, n_steps, x0)

    def expected_order(self, condition_class: str) -> int:
        """Order expected on a realisation of `condition_class` (see :func:`condition_class`)."""
        if self.kind == "implicit-midpoint":
            return 2
        return _orders(self.tableau)[condition_class if self.kind == "rkhp" else "general"]

    def expected_order_on(self, system) -> int:
        """Order expected on `system`: the class's order, bounded for an RKHP method by what
        the system's realisation allows (``truncated:K``: docs/theory.md §9)."""
        order = self.expected_order(condition_class(system))
        bound = system.realisation_order if self.kind == "rkhp" else None
        return order if bound is None else min(order, bound)


def condition_class(system) -> str:
    """The class of order conditions an RKHP method meets on `system`'s realisation: "symmetric"
    (beta(x, p) = alpha(x, -p), NOTES §8), "degenerate" (paper, eq. (degen)) or "general"."""
    if system.symmetric:
        return "symmetric"
    return "degenerate" if system.degenerate else "general"


_ORDERS: dict[tuple, dict[str, int]] = {}


def _orders(tableau) -> dict[str, int]:
    """Order per condition class of a tableau by the verify engine (cached by entries)."""
    key = (tableau.name, str(tableau.A), str(tableau.b))
    if key not in _ORDERS:
        from ..verify import verify

        orders = verify(tableau, classes=("general", "degenerate", "symmetric")).orders
        # each class's conditions follow from the previous class's (T_0 is part of T; the symmetric
        # conditions combine T_0 residuals), so its order is at least theirs: this matters where a
        # class is checked to a lower order (the symmetric relations ship up to order 8)
        general = int(orders["general"])
        degenerate = max(general, int(orders["degenerate"]))
        _ORDERS[key] = {"general": general, "degenerate": degenerate,
                        "symmetric": max(degenerate, int(orders["symmetric"]))}
    return _ORDERS[key]


def resolve_method(spec: str) -> Method:
    """The method a name stands for (InputError for an unknown name, an implicit tableau...)."""
    from ..tablefiles import load_tableau

    spec = spec.strip()
    if not spec:
        raise InputError("empty method name")
    if spec == MIDPOINT:
        return Method(spec, "implicit-midpoint")
    kind = "rkhp"
    name = spec
    if spec.startswith(CLASSICAL_PREFIX):
        kind, name = "classical", spec[len(CLASSICAL_PREFIX):]
    tableau = load_tableau(name)
    if not tableau.is_explicit:
        raise InputError(f"method {spec}: tableau {tableau.name} is {tableau.kind}; "
                         "the integrators need an explicit one")
    return Method(spec, kind, tableau)


def resolve_methods(specs) -> tuple[Method, ...]:
    """Resolve several names (the default methods when none are given); duplicates are refused."""
    specs = tuple(specs) or DEFAULT_METHODS
    if len(set(specs)) != len(specs):
        raise InputError(f"a method is named twice in {', '.join(specs)}")
    return tuple(resolve_method(s) for s in specs)
